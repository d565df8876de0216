import pytest

from strl_pyg.utils.io import _umask, atomic_open


def test_atomic_open_writes_and_replaces(tmp_path):
    path = tmp_path / "sub" / "f.txt"
    with atomic_open(path, "w") as f:
        f.write("one")
    with atomic_open(path, "w") as f:
        f.write("two")
    assert path.read_text() == "two"
    assert path.stat().st_mode & 0o777 == 0o666 & ~_umask()  # not mkstemp's 0600
    assert [p.name for p in path.parent.iterdir()] == ["f.txt"]


def test_atomic_open_failure_keeps_old_file_and_leaves_no_temporary(tmp_path):
    path = tmp_path / "f.bin"
    path.write_bytes(b"old")
    with pytest.raises(RuntimeError):
        with atomic_open(path) as f:
            f.write(b"half")
            raise RuntimeError("interrupted")
    assert path.read_bytes() == b"old"
    assert [p.name for p in tmp_path.iterdir()] == ["f.bin"]
    with pytest.raises(ValueError, match="writing mode"):
        with atomic_open(path, "rb"):
            pass
