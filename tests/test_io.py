"""Atomic outputs (regular files only, a failed write names the output, the overwrite check at
the rename) and bounded inputs."""

from __future__ import annotations

import errno
import os
import zlib
from pathlib import Path

import pytest

from wholearm_tools._io import (
    atomic_path,
    load_json,
    output_policy,
    read_text_input,
    write_text_atomic,
)
from wholearm_tools.errors import InputError, OutputError


def leftovers(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir() if p.name.startswith("."))


def test_an_output_that_appears_during_the_work_is_not_replaced(tmp_path: Path) -> None:
    target = tmp_path / "map.json"
    def write_while_another_finishes() -> None:
        with output_policy(overwrite=False), atomic_path(target) as tmp:
            tmp.write_text("ours")
            target.write_text("theirs")  # another command finished first

    with pytest.raises(OutputError, match=r"map\.json: already exists \(use --overwrite"):
        write_while_another_finishes()
    assert target.read_text() == "theirs"
    assert leftovers(tmp_path) == []
    with output_policy(overwrite=True), atomic_path(target) as tmp:
        tmp.write_text("ours")
    assert target.read_text() == "ours"
    write_text_atomic(target, "library default replaces")
    assert target.read_text() == "library default replaces"


def test_outputs_are_regular_files_or_absent(tmp_path: Path) -> None:
    fifo = tmp_path / "out.csv"
    os.mkfifo(fifo)
    with pytest.raises(OutputError, match=r"out\.csv: exists and is not a regular file"):
        write_text_atomic(fifo, "x")
    (tmp_path / "folder").mkdir()
    with pytest.raises(OutputError, match=r"folder: is a folder, not an output file"):
        write_text_atomic(tmp_path / "folder", "x")
    assert leftovers(tmp_path) == []


@pytest.mark.parametrize("during_cleanup", [False, True])
def test_a_full_disk_is_one_error_naming_the_output(tmp_path: Path,
                                                    during_cleanup: bool) -> None:
    target = tmp_path / "report.pdf"

    def writer(path: Path) -> None:
        try:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        except OSError:
            if during_cleanup:  # what the PDF backend does when its stream fails
                raise zlib.error("Error -2 while flushing") from None
            raise

    def write() -> None:
        with atomic_path(target, ".pdf") as tmp:
            writer(tmp)

    with pytest.raises(OutputError, match=r"report\.pdf: cannot write output \(No space left "
                                          r"on device\)"):
        write()
    assert list(tmp_path.iterdir()) == []


def test_inputs_are_bounded_regular_utf8_files(tmp_path: Path) -> None:
    fifo = tmp_path / "robot.urdf"
    os.mkfifo(fifo)
    with pytest.raises(InputError, match=r"robot\.urdf: not a regular file .*not a URDF"):
        read_text_input(fifo, "URDF")
    big = tmp_path / "big.csv"
    big.write_bytes(b"x" * 3000)
    with pytest.raises(InputError, match=r"big\.csv: 2\.93 KiB is too large for a table "
                                         r"\(at most 2 KiB\)"):
        read_text_input(big, "table", max_bytes=2048)
    latin = tmp_path / "latin.csv"
    latin.write_bytes("t,note\n1,caf\xe9\n".encode("latin-1"))
    with pytest.raises(InputError, match=r"latin\.csv: table is not UTF-8 text \(byte 0xe9 at "
                                         r"offset 12\)"):
        read_text_input(latin, "table")
    bom = tmp_path / "bom.csv"
    bom.write_bytes(b"\xef\xbb\xbft\n1\n")
    assert read_text_input(bom, "table") == "t\n1\n"


def test_json_depth_is_bounded(tmp_path: Path) -> None:
    assert load_json('{"a": [[1]]}', "x.json") == {"a": [[1]]}
    with pytest.raises(InputError, match=r"x\.json: map nested too deeply \(at most 8"):
        load_json("[" * 9 + "]" * 9, "x.json", "map", max_depth=8)
    with pytest.raises(InputError, match=r"x\.json: map nested too deeply"):
        load_json("[" * 200_000, "x.json", "map")
    with pytest.raises(InputError, match=r"x\.json: malformed map \(Expecting"):
        load_json("[1,", "x.json", "map")


def test_writers_see_the_output_s_own_name(tmp_path: Path) -> None:
    """Writers that record the file name (an OBJ's object name) record the output's name, so
    the output is the same on every run."""
    names = []
    for _ in range(2):
        with output_policy(overwrite=True), atomic_path(tmp_path / "map.obj", ".obj") as tmp:
            names.append(tmp.name)
            tmp.write_text(f"# object name: {tmp.stem}\n")
    assert names == ["map.obj", "map.obj"]
    assert (tmp_path / "map.obj").read_text() == "# object name: map\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["map.obj"]
