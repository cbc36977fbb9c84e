# SPDX-License-Identifier: LGPL-2.1-or-later
"""The one atomic-output helper: all or nothing, never over an input, permissions kept."""
import os
import signal
import stat
import time

import pytest

from core.errors import ParameterError
from core.output_files import (atomic_output, interrupts_held, output_transaction,
                               write_json_atomic, write_text_atomic)


def test_a_failed_write_leaves_the_old_file_and_no_temporary(tmp_path):
    target = tmp_path / "out.step"
    target.write_text("old")
    with pytest.raises(RuntimeError, match="writer failed"):
        with atomic_output(target) as temporary:
            assert os.path.dirname(temporary) == str(tmp_path)
            assert temporary.endswith(".tmp.step"), "writers choosing a format by suffix see it"
            with open(temporary, "w") as stream:
                stream.write("half")
            raise RuntimeError("writer failed")
    assert target.read_text() == "old"
    assert sorted(os.listdir(tmp_path)) == ["out.step"]


def test_the_replaced_file_keeps_its_permissions(tmp_path):
    target = tmp_path / "report.json"
    target.write_text("{}")
    os.chmod(target, 0o600)
    write_json_atomic(target, {"a": 1})
    assert target.read_text() == '{\n  "a": 1\n}\n'
    assert stat.S_IMODE(os.stat(target).st_mode) == 0o600
    fresh = tmp_path / "new.txt"
    mask = os.umask(0)
    os.umask(mask)
    write_text_atomic(fresh, "x")
    assert stat.S_IMODE(os.stat(fresh).st_mode) == 0o666 & ~mask


def test_an_input_is_never_written_even_through_a_link(tmp_path):
    source = tmp_path / "target.stl"
    source.write_text("solid")
    link = tmp_path / "link.stl"
    link.symlink_to(source)
    for path in (source, link):
        with pytest.raises(ParameterError, match="refusing to overwrite the input file"):
            with atomic_output(path, inputs=(source,)):
                pytest.fail("the block must not run")
    assert source.read_text() == "solid"
    assert sorted(os.listdir(tmp_path)) == ["link.stl", "target.stl"]


def test_a_transaction_writes_every_output_at_its_end_or_none(tmp_path):
    report, step = tmp_path / "report.json", tmp_path / "out.step"
    report.write_text("old report")
    with output_transaction():
        write_text_atomic(step, "new step")
        write_json_atomic(report, {"a": 1})
        assert not step.exists() and report.read_text() == "old report", \
            "nothing is renamed before the transaction ends"
    assert step.read_text() == "new step" and report.read_text() == '{\n  "a": 1\n}\n'
    assert sorted(os.listdir(tmp_path)) == ["out.step", "report.json"]
    for failure in (KeyboardInterrupt, RuntimeError):
        with pytest.raises(failure):
            with output_transaction():
                write_text_atomic(step, "newer step")
                write_json_atomic(report, {"b": 2})
                raise failure()
        assert step.read_text() == "new step" and report.read_text() == '{\n  "a": 1\n}\n'
        assert sorted(os.listdir(tmp_path)) == ["out.step", "report.json"], "no temporary left"


def test_a_failed_write_caught_inside_a_transaction_is_not_committed(tmp_path):
    kept, failed = tmp_path / "kept.txt", tmp_path / "failed.txt"
    with output_transaction():
        write_text_atomic(kept, "complete")
        with pytest.raises(RuntimeError):
            with atomic_output(failed) as temporary:
                with open(temporary, "w") as stream:
                    stream.write("half")
                raise RuntimeError("writer failed")
    assert sorted(os.listdir(tmp_path)) == ["kept.txt"]
    assert kept.read_text() == "complete"


def test_ctrl_c_in_a_held_block_arrives_when_it_ends_or_is_dropped():
    reached = []
    with pytest.raises(KeyboardInterrupt):
        with interrupts_held():
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(0.05)  # let the signal be handled inside the block
            reached.append("end of block")
    assert reached == ["end of block"], "the block ran to its end before the KeyboardInterrupt"
    with interrupts_held(redeliver=False):
        os.kill(os.getpid(), signal.SIGINT)
        time.sleep(0.05)
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
