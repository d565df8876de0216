"""The on-disk match cache: keys, fingerprints, resumption after interruption (a limit and a
killed process), failure markers, corrupt entries and parallel builds."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from strl_pyg.data import PairMatches
from strl_pyg.datasets import MatchCache, PairFailedError, cache_key, fingerprint_hash

TESTS_DIR = Path(__file__).resolve().parent  # holds this module (the killed build imports it)
REPO = Path(__file__).resolve().parents[2]


class FakeNoMatches(ValueError):
    pass


def fake_match(payload) -> PairMatches:
    """Deterministic stand-in for the front end: seeds ``% 5 == 3`` have no matches."""
    seed, delay = (payload, 0.0) if isinstance(payload, int) else payload
    if delay:
        time.sleep(delay)
    if seed % 5 == 3:
        raise FakeNoMatches(f"no matches for seed {seed}")
    rng = np.random.default_rng(seed)
    n = 5 + seed % 7
    p0 = rng.uniform(0, 63, (n, 2))
    lines = rng.uniform(0, 63, (2, 2, 2))
    return PairMatches(
        p0, p0 + 0.5, lines0=lines, lines1=lines + 0.25, image_size0=(64, 64),
        image_size1=(64, 64), point_scores=rng.uniform(size=n),
        image0=rng.integers(0, 255, (64, 64), dtype=np.uint8),
        image1=rng.integers(0, 255, (64, 64), dtype=np.uint8),
        info={"seed": seed},
    )


def _keys(n: int) -> list[str]:
    return [cache_key(f"fake/{i}") for i in range(n)]


def _build(cache: MatchCache, n: int, **kw):
    return cache.build(_keys(n), list(range(n)), fake_match, skip_errors=(FakeNoMatches,),
                       progress=False, **kw)


def _snapshot(cache: MatchCache) -> dict[str, object]:
    """Every entry's arrays (exact) or failure marker, by file name."""
    out = {}
    for p in sorted(cache.dir.iterdir()):
        if p.suffix == ".npz":
            with np.load(p) as z:
                out[p.name] = {k: z[k] for k in z.files}
        elif p.suffix == ".failed":
            out[p.name] = json.loads(p.read_text())
    return out


def _assert_same(a: dict, b: dict) -> None:
    assert sorted(a) == sorted(b)
    for name in a:
        if isinstance(a[name], dict) and name.endswith(".npz"):
            assert sorted(a[name]) == sorted(b[name]), name
            for k in a[name]:
                np.testing.assert_array_equal(a[name][k], b[name][k], err_msg=f"{name}:{k}")
        else:
            assert a[name] == b[name], name


def test_cache_key_is_safe_distinct_and_stable():
    k1, k2 = cache_key("demon/test/a~b/0-1"), cache_key("demon/test/a_b/0-1")
    assert k1 != k2
    assert k1 == cache_key("demon/test/a~b/0-1")
    assert all(c.isalnum() or c in "._-" for c in k1)
    assert k1.startswith("demon_test_a_b_0-1-")
    with pytest.raises(ValueError, match="Expected a non-empty string pair id"):
        cache_key("")


def test_fingerprint_selects_the_folder(tmp_path):
    a = MatchCache(tmp_path, {"frontend": {"max_keypoints": 512}, "image_size": (128, 416)})
    b = MatchCache(tmp_path, {"image_size": (128, 416), "frontend": {"max_keypoints": 512}})
    c = MatchCache(tmp_path, {"frontend": {"max_keypoints": 1024}, "image_size": (128, 416)})
    d = MatchCache(tmp_path, {"frontend": {"max_keypoints": 512}, "image_size": (192, 256)})
    assert a.dir == b.dir  # key order does not matter
    assert len({a.dir, c.dir, d.dir}) == 3
    assert a.dir.name == fingerprint_hash(a.fingerprint)
    _build(a, 2)
    meta = json.loads((a.dir / "fingerprint.json").read_text())
    assert meta["frontend"] == {"max_keypoints": 512}
    assert not c.dir.exists()  # a changed config reuses nothing


def test_build_writes_entries_and_failure_markers(tmp_path):
    cache = MatchCache(tmp_path, {"test": 1})
    report = _build(cache, 10)
    assert (report.computed, report.failed, report.remaining) == (8, 2, 0)
    assert report.complete
    for i, key in enumerate(_keys(10)):
        if i % 5 == 3:
            assert cache.status(key) == "failed"
            with pytest.raises(PairFailedError, match="failure marker"):
                cache.load(key)
            marker = json.loads(cache.failed_path(key).read_text())
            assert "no matches for seed" in marker["message"]
        else:
            m = cache.load(key)
            np.testing.assert_array_equal(m.points0, fake_match(i).points0)
            assert m.info == {"seed": i}
    # A rerun does nothing: done and failed pairs are not retried.
    again = _build(cache, 10)
    assert (again.already_done, again.already_failed, again.computed, again.failed) == (8, 2, 0, 0)
    assert not list(cache.dir.glob(".*.tmp"))


def test_interrupted_build_resumes_to_the_same_cache(tmp_path):
    ref = MatchCache(tmp_path / "ref", {"test": 1})
    _build(ref, 12)
    cache = MatchCache(tmp_path / "run", {"test": 1})
    first = _build(cache, 12, max_pairs=5)  # "interrupted" after 5 pairs
    assert first.computed + first.failed == 5 and first.remaining == 7
    assert not first.complete
    assert len(_snapshot(cache)) == 5
    second = _build(cache, 12)
    assert second.already_done + second.already_failed == 5
    assert second.computed + second.failed == 7 and second.complete
    _assert_same(_snapshot(ref), _snapshot(cache))


_KILL_SCRIPT = """
import sys
sys.path.insert(0, {tests!r})
from test_cache import _keys, fake_match, FakeNoMatches
from strl_pyg.datasets import MatchCache
cache = MatchCache({root!r}, {{"test": 1}})
n = {n}
cache.build(_keys(n), [(i, 0.15) for i in range(n)], fake_match,
            skip_errors=(FakeNoMatches,), progress=False)
"""


@pytest.mark.slow
def test_killed_build_leaves_no_corrupt_entry_and_resumes(tmp_path):
    n = 14
    script = tmp_path / "build.py"
    script.write_text(_KILL_SCRIPT.format(tests=str(TESTS_DIR), root=str(tmp_path / "run"), n=n))
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    proc = subprocess.Popen([sys.executable, str(script)], env=env, stderr=subprocess.PIPE)
    cache = MatchCache(tmp_path / "run", {"test": 1})
    deadline = time.time() + 60
    while time.time() < deadline and proc.poll() is None:
        if cache.dir.is_dir() and len(list(cache.dir.glob("*.npz"))) >= 4:
            break
        time.sleep(0.02)
    assert proc.poll() is None, proc.stderr.read().decode()[-2000:]
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    before = _snapshot(cache)
    assert 4 <= len(before) < n
    for name in before:  # everything that exists loads
        if name.endswith(".npz"):
            PairMatches.load(cache.dir / name)
    resumed = cache.build(_keys(n), list(range(n)), fake_match, skip_errors=(FakeNoMatches,),
                          progress=False)
    assert resumed.already_done + resumed.already_failed == len(before)
    assert resumed.computed + resumed.failed == n - len(before)
    ref = MatchCache(tmp_path / "ref", {"test": 1})
    _build(ref, n)
    _assert_same(_snapshot(ref), _snapshot(cache))


def test_corrupt_and_missing_entries_give_clear_errors(tmp_path):
    cache = MatchCache(tmp_path, {"test": 1})
    keys = _keys(3)
    with pytest.raises(FileNotFoundError, match="build the cache first") as err:
        cache.load(keys[0])
    assert str(cache.path(keys[0])) in str(err.value)
    _build(cache, 3)
    path = cache.path(keys[1])
    path.write_bytes(path.read_bytes()[:100])  # truncated, as by a copy gone wrong
    assert cache.status(keys[1]) == "corrupt"
    assert cache.status(keys[1], verify=False) == "done"
    with pytest.raises(ValueError, match="Expected a readable .npz match file") as err:
        cache.load(keys[1])
    assert str(path) in str(err.value)
    with pytest.warns(UserWarning, match="Corrupt cache entry"):
        report = _build(cache, 3)
    assert (report.corrupt_redone, report.computed) == (1, 1)
    np.testing.assert_array_equal(cache.load(keys[1]).points0, fake_match(1).points0)


def test_other_errors_stop_the_build_and_keep_finished_entries(tmp_path):
    cache = MatchCache(tmp_path, {"test": 1})

    def broken(seed):
        if seed == 2:
            raise FileNotFoundError("Expected an image file at '/nowhere.png' (got no such file)")
        return fake_match(seed)

    with pytest.raises(FileNotFoundError, match="/nowhere.png"):
        cache.build(_keys(4), list(range(4)), broken, progress=False)
    assert cache.status(_keys(4)[0]) == "done" and cache.status(_keys(4)[1]) == "done"
    assert cache.status(_keys(4)[2]) == "missing"


def test_build_validates_arguments(tmp_path):
    cache = MatchCache(tmp_path, {"test": 1})
    with pytest.raises(ValueError, match="Expected one payload per key"):
        cache.build(_keys(2), [0], fake_match)
    with pytest.raises(ValueError, match="Expected unique keys"):
        cache.build(["a", "a"], [0, 1], fake_match)
    with pytest.raises(ValueError, match="Expected num_workers >= 0"):
        cache.build(_keys(1), [0], fake_match, num_workers=-1)
    with pytest.raises(TypeError, match="Expected the match function to return a PairMatches"):
        cache.build(_keys(1), [0], lambda s: None, progress=False)


@pytest.mark.slow  # spawns two worker processes (~7 s)
def test_parallel_build_matches_serial_build(tmp_path):
    serial = MatchCache(tmp_path / "serial", {"test": 1})
    _build(serial, 8)
    par = MatchCache(tmp_path / "par", {"test": 1})
    report = _build(par, 8, num_workers=2)  # spawned worker processes
    assert (report.computed, report.failed) == (7, 1)
    _assert_same(_snapshot(serial), _snapshot(par))


def test_entries_of_the_format_before_dedupe_are_not_read(tmp_path, monkeypatch):
    """Review finding: the front end started dropping repeated point matches without a new
    fingerprint, so a cache built before served the repeats to the new code. Entries written
    under format 1 live in another folder and are not read now."""
    import strl_pyg.datasets.cache as cache_mod

    fp = {"kind": "fake", "frontend": {"max_keypoints": 512}}
    monkeypatch.setattr(cache_mod, "CACHE_FORMAT_VERSION", 1)
    old = MatchCache(tmp_path, fp)
    _build(old, 3)
    assert old.status(_keys(3)[0]) == "done"
    monkeypatch.undo()
    assert cache_mod.CACHE_FORMAT_VERSION >= 2
    new = MatchCache(tmp_path, fp)
    assert new.dir != old.dir
    assert [new.status(k) for k in _keys(3)] == ["missing"] * 3


def test_counts_read_the_match_arrays_once_and_follow_a_rewritten_entry(tmp_path, monkeypatch):
    cache = MatchCache(tmp_path, {"kind": "fake"})
    _build(cache, 8)
    keys = _keys(8)
    counts = cache.counts(keys)
    expected = {k: (PairMatches.load(cache.path(k)).num_points, 2) for k in keys
                if cache.path(k).is_file()}
    assert counts == expected and len(counts) == 7  # seed 3 has no matches: left out
    assert (cache.dir / "counts.json").is_file()

    def no_reading(*args, **kwargs):
        raise AssertionError("an entry was read again")

    monkeypatch.setattr(np, "load", no_reading)
    assert cache.counts(keys) == expected  # from counts.json alone
    monkeypatch.undo()
    fewer = fake_match(0).select(np.arange(2))
    fewer.save(cache.path(keys[0]))
    os.utime(cache.path(keys[0]), ns=(1, 1))  # a rewritten entry: another stamp
    assert cache.counts(keys[:1]) == {keys[0]: (2, 2)}


def test_a_dataset_leaves_out_pairs_with_few_matches(tmp_path):
    from strl_pyg.data import build_pair_graph
    from strl_pyg.datasets.base import CachedPairDataset

    class FakePairs(CachedPairDataset):
        def _match_fn(self):
            return fake_match

        def _payload(self, i):
            return i

        def _skip_errors(self):
            return (FakeNoMatches,)

        def _graph(self, i, matches):
            return build_pair_graph(matches)

    everything = FakePairs(_keys(20), tmp_path, lambda: {"kind": "fake"})
    with pytest.warns(UserWarning, match="gave no matches"):
        everything.build_cache(progress=False)
    few = FakePairs(_keys(20), tmp_path, lambda: {"kind": "fake"}, min_points=9)
    with pytest.warns(UserWarning, match="fewer than min_points=9"):
        kept = [few.load_matches(i).num_points for i in range(len(few))]
    assert kept and min(kept) >= 9
    assert len(few) == sum(1 for s in range(20) if s % 5 != 3 and 5 + s % 7 >= 9)
    with pytest.raises(ValueError, match="Expected min_points as an integer >= 0"):
        FakePairs(_keys(2), tmp_path, lambda: {"kind": "fake"}, min_points=-1)
