# SPDX-License-Identifier: LGPL-2.1-or-later
"""Bytes through temporary files (polycube_wb.file_bytes): what a path-only writer writes comes
back as bytes, bytes reach a path-only reader, and no file is left behind, even on an error."""
import glob
import os
import tempfile

import pytest

from polycube_wb.file_bytes import bytes_written_by, read_from_bytes

pytestmark = pytest.mark.unit


def leftovers():
    return set(glob.glob(os.path.join(tempfile.gettempdir(), "polycube-*")))


def test_bytes_go_through_a_file_and_back():
    before = leftovers()
    seen = []

    def write(path):
        seen.append(os.path.basename(path))
        with open(path, "wb") as handle:
            handle.write(b"\x00shape\xff")

    data = bytes_written_by(write, "shape.bin")
    assert data == b"\x00shape\xff" and seen == ["shape.bin"]

    def read(path):
        with open(path, "rb") as handle:
            return handle.read(), os.path.basename(path)

    assert read_from_bytes(data, "mesh.bms", read) == (data, "mesh.bms")
    assert leftovers() == before


def test_a_failing_reader_leaves_no_file():
    before = leftovers()

    def read(path):
        raise ValueError("not a shape")

    with pytest.raises(ValueError, match="not a shape"):
        read_from_bytes(b"junk", "shape.bin", read)
    assert leftovers() == before
