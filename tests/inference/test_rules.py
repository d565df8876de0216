"""The rules as records (strl_pyg.inference.rules, strl_pyg.inference.status): the status enum,
verdicts naming their rule in the record and the JSON, the sigma cap, the rules table in the
docs, a rule as one module, and no status literal outside the enum's module."""

from __future__ import annotations

import io
import json
import tokenize
from pathlib import Path

import numpy as np
import pytest

from strl_pyg.estimation.uncertainty import MAX_SIGMA_DEG, cap_covariance
from strl_pyg.inference import PoseEstimator
from strl_pyg.inference.record import MethodResult, PoseEstimate
from strl_pyg.inference.rules import (
    PoseRule,
    ordered_rules,
    register_rule,
    rules_table,
    unregister_rule,
)
from strl_pyg.inference.rules.registry import RULES
from strl_pyg.inference.rules.sigma_cap import SigmaCap
from strl_pyg.inference.status import STATUSES, Action, Status, Verdict  # noqa: F401

ROOT = Path(__file__).resolve().parents[2]


def test_status_is_its_string():
    assert Status.OK == "ok" and "ok" == Status.OK and str(Status.FAILED) == "failed"
    assert f"{Status.ROTATION_ONLY:<14}|" == "rotation_only |"
    assert {"ok": 0}[Status.OK] == 0 and {Status.OK: 1}["ok"] == 1  # hashed as its string
    assert json.dumps({"s": Status.UNRELIABLE}) == '{"s": "unreliable"}'
    assert STATUSES == ("ok", "rotation_only", "unreliable", "degenerate", "failed", "skipped")
    assert MethodResult("x", "failed").status is Status.FAILED
    with pytest.raises(ValueError, match="Expected status in"):
        Status.of("fine")


def _capped_estimate(block: slice) -> PoseEstimate:
    cov = np.eye(5) * 1e-6
    cov[block, block] = np.eye(cov[block, block].shape[0]) * 10.0  # RMS angle far past 180 deg
    cov, capped = cap_covariance(cov)
    assert capped
    pose = MethodResult("poselib", "ok", np.eye(4), cov)
    return PoseEstimate(pose, {"poselib": pose}, 100, 0)


@pytest.mark.parametrize("block", [slice(0, 3), slice(3, 5)], ids=["rotation", "translation"])
def test_no_ok_pose_carries_a_capped_sigma(block):
    """Before: poses whose sigma reached the 180-deg cap came back "ok" (a temple pair 15 / 8
    deg off, a wide indoor pair 133 / 129 deg off), so "ok" meant nothing there."""
    est = _capped_estimate(block)
    assert max(est.pose.sigma.values()) == pytest.approx(MAX_SIGMA_DEG)
    verdict = SigmaCap()(est, None)
    assert est.pose.status == "unreliable" and est.pose.rule == "sigma_cap"
    assert verdict is est.pose.verdicts[-1] and verdict.action == "refused"
    np.testing.assert_array_equal(est.pose.info["unreliable_T_0to1"], np.eye(4))
    assert "180-deg cap" in est.pose.warnings[-1]
    # below the cap nothing is said
    sharp = MethodResult("poselib", "ok", np.eye(4), np.eye(5) * 1e-4)
    est = PoseEstimate(sharp, {"poselib": sharp}, 100, 0)
    assert SigmaCap()(est, None) is None and est.pose.status == "ok"


def test_every_refusal_names_its_rule_in_the_json():
    """The status and its rule come from the records, not from matching warning text: an
    unsupported pose names "support", an input with too few matches "too_few_matches"."""
    rng = np.random.default_rng(0)
    K = np.array([[500.0, 0, 319.5], [0, 500.0, 239.5], [0, 0, 1]])
    from strl_pyg import PairMatches

    size = [639, 479]
    m = PairMatches(rng.uniform(0, size, (300, 2)), rng.uniform(0, size, (300, 2)), K0=K, K1=K,
                    image_size0=(480, 640), image_size1=(480, 640))
    est = PoseEstimator(methods=("poselib", "opencv"), bootstrap=0).estimate(m)
    assert est.pose.status == "failed" and est.pose.rule == "support"
    js = json.loads(json.dumps(est.to_dict(), allow_nan=False))
    assert js["pose"]["rule"] == "support"
    assert js["methods"]["poselib"]["verdicts"][-1]["rule"] == "support"
    few = PairMatches(m.points0[:3], m.points1[:3], K0=K, K1=K, image_size0=(480, 640),
                      image_size1=(480, 640))
    est = PoseEstimator(methods=("poselib",), bootstrap=0).estimate(few)
    assert est.pose.status == "degenerate" and est.pose.rule == "too_few_matches"


def test_rules_run_in_order_and_the_docs_table_is_the_registry():
    names = [r.name for r in ordered_rules()]
    assert names == ["watermark", "multiple", "configuration", "focal", "sigma_cap"]
    assert names == sorted(RULES, key=lambda n: RULES[n].order)
    text = (ROOT / "docs" / "rules.md").read_text()
    assert rules_table() in text


class _Shout(PoseRule):
    name = "shout"
    summary = "reports every ok pose"
    order = 95.0

    def __call__(self, estimate, run):
        if estimate.pose.status != Status.OK:
            return None
        return Verdict(self.name, Action.REPORTED, Status.OK, "heard",
                       {"n": run.matches.num_points})


def test_a_rule_registered_at_run_time_speaks_on_every_pose(generated_pair):

    register_rule(_Shout)
    try:
        with pytest.raises(ValueError, match="Expected a new rule name"):
            register_rule(_Shout)
        est = PoseEstimator(methods=("poselib",), bootstrap=0).estimate(
            generated_pair(2_000_017).matches)
        assert est.pose.status == "ok" and est.pose.verdicts[-1].rule == "shout"
        assert est.pose.verdicts[-1].evidence["n"] == est.matches.num_points
    finally:
        unregister_rule("shout")
    assert "shout" not in RULES
    with pytest.raises(TypeError, match="Expected a PoseRule"):
        register_rule(object())


PLUGIN = '''
from strl_pyg.inference.rules import PoseRule
from strl_pyg.inference.status import Status


class FewInliers(PoseRule):
    name = "few_inliers"
    summary = "refuses a pose with fewer than 10000 inliers"
    order = 85.0
    decides = "refuse"

    def __call__(self, estimate, run):
        pose = estimate.pose
        if pose.status != Status.OK or (pose.num_inliers or 0) >= 10000:
            return None
        estimate.pose = pose.unreliable(["fewer than 10000 inliers"], rule=self.name,
                                        evidence={"inliers": pose.num_inliers})
        return estimate.pose.verdicts[-1]
'''


@pytest.mark.slow
def test_a_new_rule_is_one_module(tmp_path, plugin_cli, generated_pair):
    """A package that declares one module in the ``strl-pyg.rules`` entry-point group adds a
    rule: ``strl-pose rules`` lists it, ``predict`` applies it and its name is the record's
    ``rule``."""

    cli = plugin_cli("few_inliers", PLUGIN, "strl-pyg.rules",
                     "few_inliers = few_inliers:FewInliers")
    generated_pair(2_000_017).matches.save(tmp_path / "pair.npz")

    assert "| `few_inliers` | the recommended pose | refuse |" in cli("rules")
    record = json.loads(cli("predict", "--matches", str(tmp_path / "pair.npz"), "--methods",
                            "poselib", "--json", "--bootstrap", "0", code=3))
    assert record["pose"]["status"] == "unreliable" and record["pose"]["rule"] == "few_inliers"
    assert record["pose"]["verdicts"][-1]["evidence"]["inliers"] > 0


#: where a status name may appear as a string: the enum's own module, and names that are no
#: pose status (a cache entry's, a line matcher's, a training log's, a configuration's)
_NOT_STATUSES = {"strl_pyg/inference/status.py", "strl_pyg/datasets/cache.py",
                 "strl_pyg/training/loop.py", "strl_pyg/training/skipped.py",
                 "strl_pyg/frontend/pipeline.py", "strl_pyg/estimation/two_view.py"}


def test_no_status_literal_outside_the_enum():
    """Statuses are compared and set as :class:`Status` members; the string ``"unreliable"``
    stays only as the ``info`` key of the refusal's reasons."""
    names = {f'"{s}"' for s in STATUSES} | {f"'{s}'" for s in STATUSES}
    found = []
    for path in sorted((ROOT / "strl_pyg").rglob("*.py")):
        rel = path.relative_to(ROOT).as_posix()
        if rel in _NOT_STATUSES:
            continue
        toks = [t for t in tokenize.generate_tokens(io.StringIO(path.read_text()).readline)
                if t.type not in (tokenize.NL, tokenize.NEWLINE, tokenize.COMMENT,
                                  tokenize.INDENT, tokenize.DEDENT)]
        for i, t in enumerate(toks):
            if t.type != tokenize.STRING or t.string not in names:
                continue
            before, after = toks[i - 1].string, toks[i + 1].string
            as_key = before == "[" or after == ":" or (before == "(" and toks[i - 2].string
                                                       == "get")
            if t.string.strip("\"'") == "unreliable" and as_key:
                continue
            found.append(f"{rel}:{t.start[0]}")
    assert not found, found
