"""The one atomic writer: never replaces what is not a regular file, never leaves half a file."""

import errno
import os
import stat

import numpy as np
import pytest

import common
import common.files


def test_write_replaces_a_regular_file_whole(tmp_path):
    p = tmp_path / "r.json"
    p.write_text("old")
    common.write_json(p, {"a": 1})
    assert p.read_text() == '{\n  "a": 1\n}\n'
    assert sorted(os.listdir(tmp_path)) == ["r.json"]
    assert oct(p.stat().st_mode & 0o777) == oct(0o644)


@pytest.mark.parametrize("kind", ["symlink", "fifo", "folder"])
def test_a_path_that_is_not_a_regular_file_is_never_replaced(tmp_path, kind):
    p = tmp_path / "x"
    target = tmp_path / "target.txt"
    target.write_text("keep")
    if kind == "symlink":
        p.symlink_to(target)
    elif kind == "fifo":
        os.mkfifo(p)
    else:
        p.mkdir()
    with pytest.raises(FileExistsError, match="not a regular file"):
        common.write_text(p, "new")
    assert target.read_text() == "keep"
    assert (
        common.path_kind(p)
        == {"symlink": "a symlink", "fifo": "a FIFO", "folder": "a folder"}[kind]
    )
    assert sorted(os.listdir(tmp_path)) == ["target.txt", "x"]


def test_a_character_device_is_never_replaced(tmp_path):
    """A device node of our own (never the machine's /dev/null: a regression would replace it)."""
    node = tmp_path / "null"
    try:
        os.mknod(node, stat.S_IFCHR | 0o666, os.makedev(1, 3))
    except PermissionError:
        pytest.skip("making a device node needs CAP_MKNOD")
    with pytest.raises(FileExistsError, match="a character device"):
        common.write_text(node, "x")
    assert stat.S_ISCHR(os.lstat(node).st_mode)


def _full_disk(path, data):
    with open(path, "wb") as f:
        f.write(data[: len(data) // 2])
    raise OSError(errno.ENOSPC, "No space left on device")


@pytest.mark.parametrize(
    "write",
    [
        lambda p: common.write_json(p, {"x": list(range(100))}),
        lambda p: common.write_png(p, np.zeros((8, 8, 3), np.uint8)),
        lambda p: common.files.write_torch(p, {"w": np.arange(10)}),
    ],
)
def test_a_full_disk_names_the_file_and_leaves_the_old_one(tmp_path, monkeypatch, write):
    p = tmp_path / "out.bin"
    p.write_bytes(b"old results")
    monkeypatch.setattr(common.files, "_write_file", _full_disk)
    with pytest.raises(OSError) as info:
        write(p)
    assert info.value.errno == errno.ENOSPC and info.value.filename == str(p)
    assert str(p) in str(info.value) and "\n" not in str(info.value)
    assert p.read_bytes() == b"old results"
    assert sorted(os.listdir(tmp_path)) == ["out.bin"]  # no temporary file left


def test_a_png_that_cannot_be_encoded_is_refused_before_anything_is_written(tmp_path):
    with pytest.raises(ValueError, match="PNG"):
        common.write_png(tmp_path / "a.png", np.zeros((4, 4, 3), np.float32))
    assert os.listdir(tmp_path) == []


def test_write_png_round_trips_through_the_loader(tmp_path):
    rng = np.random.default_rng(0)
    rgb = rng.integers(0, 256, (5, 7, 3), dtype=np.uint8)
    common.write_png(tmp_path / "a.png", rgb)
    assert np.array_equal(
        np.round(common.read_image(tmp_path / "a.png") * 255).astype(np.uint8), rgb
    )


def test_write_files_replaces_all_or_none(tmp_path, monkeypatch):
    """A full disk at the second file of a set leaves both old files and no temporary file."""
    a, b = tmp_path / "a.png", tmp_path / "b.json"
    a.write_bytes(b"old a")
    b.write_bytes(b"old b")
    write = common.files._write_file

    def full_at_b(path, data):
        return (_full_disk if path.name.startswith(".b.json.") else write)(path, data)

    monkeypatch.setattr(common.files, "_write_file", full_at_b)
    with pytest.raises(OSError) as info:
        common.write_files({a: b"new a", b: b"new b"})
    assert info.value.errno == errno.ENOSPC and info.value.filename == str(b)
    assert (a.read_bytes(), b.read_bytes()) == (b"old a", b"old b")
    assert sorted(os.listdir(tmp_path)) == ["a.png", "b.json"]
    monkeypatch.setattr(common.files, "_write_file", write)
    assert common.write_files({a: b"new a", b: b"new b"}) == [a, b]
    assert (a.read_bytes(), b.read_bytes()) == (b"new a", b"new b")
