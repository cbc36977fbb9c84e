# SPDX-License-Identifier: LGPL-2.1-or-later
"""``StageLines``: the stage lines, and a Ctrl-C that no library can lose or turn into a crash."""
import io
import os
import signal
import sys
import time

import pytest

from polycube_wb.stage_lines import STAGE_PREFIX, StageLines

SLOW_MODULE = """
import os, signal, time
os.kill(os.getpid(), signal.SIGINT)
time.sleep(0.05)  # the handler runs here, inside the import
try:
    import json
except BaseException:  # what trimesh does around its optional imports
    pass
LOADED = True
"""


def test_each_stage_is_announced_once_and_remembered():
    stream = io.StringIO()
    stages = StageLines(stream, stage="reconstruct")
    for stage, fraction in (("intake", 0.0), ("intake", 0.1), ("not a stage", 0.2), ("fit", 0.5),
                            ("fit", 0.6), ("solid", 1.0)):
        stages.report(stage, fraction)
    assert stream.getvalue().splitlines() == [STAGE_PREFIX + s for s in ("intake", "fit", "solid")]
    assert stages.stage == "solid"
    quiet = StageLines(stream=None, echo=False)
    quiet.report("parts", 0.0)
    assert quiet.stage == "parts"


def test_ctrl_c_outside_an_import_stops_the_run_there_and_again_at_the_next_report():
    stages = StageLines(echo=False)
    with stages.ctrl_c_remembered():
        with pytest.raises(KeyboardInterrupt):
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(5)  # the handler interrupts the sleep
            pytest.fail("Ctrl-C did not stop the block")
        with pytest.raises(KeyboardInterrupt):  # a library swallowed it: the next report
            stages.report("fit", 0.5)
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


def test_ctrl_c_during_an_import_waits_for_the_next_report(tmp_path, monkeypatch):
    (tmp_path / "slow_module_for_ctrl_c.py").write_text(SLOW_MODULE)
    monkeypatch.syspath_prepend(str(tmp_path))
    stages = StageLines(echo=False)
    with stages.ctrl_c_remembered():
        import slow_module_for_ctrl_c
        assert slow_module_for_ctrl_c.LOADED, "the import ran to its end"
        with pytest.raises(KeyboardInterrupt):
            stages.check_cancel()
    sys.modules.pop("slow_module_for_ctrl_c", None)
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
