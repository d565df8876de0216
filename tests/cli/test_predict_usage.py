"""``strl-pose predict``: what a new user met (each reproduced before its fix): ``--png`` with
``--json`` or ``--pairs``, images beside ``--pairs``, the exit code of a pair without a pose,
a negative number leading ``--K``, ``--matcher``, and a 4-number K in Python."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from strl_pyg.cli import main as cli_main


@pytest.fixture
def pair_files(tmp_path, held_out_pair):
    for i, img in enumerate((held_out_pair.image0, held_out_pair.image1)):
        cv2.imwrite(str(tmp_path / f"{i}.png"), img)
    K = held_out_pair.K
    return tmp_path, f"{K[0, 0]},{K[1, 1]},{K[0, 2]},{K[1, 2]}"


def test_png_with_json_draws_and_keeps_stdout_json(pair_files, capsys):
    d, K = pair_files
    code = cli_main(["predict", str(d / "0.png"), str(d / "1.png"), "--K", K, "--json",
                     "--png", str(d / "pose.png")])
    cap = capsys.readouterr()
    assert code == 0 and json.loads(cap.out)["pose"]["status"] == "ok"
    assert (d / "pose.png").is_file() and "drawing ->" in cap.err


def test_pairs_refuses_images_and_png_beside_it(pair_files, capsys):
    d, K = pair_files
    (d / "pairs.txt").write_text("0.png 1.png\n")
    assert cli_main(["predict", str(d / "0.png"), str(d / "1.png"), "--pairs",
                     str(d / "pairs.txt"), "--image-dir", str(d), "--K", K]) == 2
    assert "Expected either two images or --pairs (got both" in capsys.readouterr().err
    assert cli_main(["predict", "--pairs", str(d / "pairs.txt"), "--image-dir", str(d),
                     "--K", K, "--png", str(d / "p.png")]) == 2
    assert "Expected --png / --explain with one pair" in capsys.readouterr().err


def test_pairs_exit_1_when_a_pair_has_no_pose(pair_files, capsys):
    d, K = pair_files
    cv2.imwrite(str(d / "black.png"), np.zeros((240, 320), np.uint8))
    (d / "pairs.txt").write_text("0.png 1.png\n0.png black.png\n")
    code = cli_main(["predict", "--pairs", str(d / "pairs.txt"), "--image-dir", str(d),
                     "--K", K])
    rows = [json.loads(x) for x in capsys.readouterr().out.splitlines()]
    assert [r["pose"]["status"] for r in rows] == ["ok", "degenerate"]
    assert code == 1
    (d / "good.txt").write_text("0.png 1.png\n")
    assert cli_main(["predict", "--pairs", str(d / "good.txt"), "--image-dir", str(d),
                     "--K", K]) == 0


def test_a_negative_number_may_lead_K(pair_files, capsys):
    """Before: argparse's 'expected one argument'; now K is read and checked."""
    d, K = pair_files
    code = cli_main(["predict", str(d / "0.png"), str(d / "1.png"), "--K",
                     "-293," + K.split(",", 1)[1]])
    err = capsys.readouterr().err
    assert code == 2 and "expected one argument" not in err
    assert "Expected" in err and "-293" in err


def test_matcher_preset_reaches_the_front_end(pair_files, capsys, monkeypatch):
    import strl_pyg.frontend as fe
    from strl_pyg.frontend import FrontendConfig

    seen = []
    real = fe.match_images

    def spy(*a, config=None, **k):
        seen.append(config)
        return real(*a, config=config, **k)

    monkeypatch.setattr(fe, "match_images", spy)
    d, K = pair_files
    assert cli_main(["match", str(d / "0.png"), str(d / "1.png"), "--K", K, "--matcher",
                     "thorough", "--out", str(d / "m.npz")]) == 0
    want = FrontendConfig.preset("thorough")
    assert seen and all(c.result_fields() == want.result_fields() for c in seen)


def test_estimate_images_with_four_numbers_as_K_is_one_line(held_out_pair):
    """Before: IndexError 'too many indices for array' from the intrinsics checks."""
    from strl_pyg.inference import PoseEstimator

    with pytest.raises(ValueError, match=r"Expected 'K0' of shape \(3, 3\) \(got \(4,\)\): "
                                         r"four numbers \(fx, fy, cx, cy\)"):
        PoseEstimator().estimate_images(held_out_pair.image0, held_out_pair.image1,
                                        K0=(500.0, 500.0, 320.0, 240.0))


def test_the_picture_is_in_colour_and_its_header_fits(tmp_path, held_out_pair, capsys):
    """Before: colour photographs were drawn grey and a small image's header was cut off
    ("(poselib, unr")."""
    from strl_pyg.viz.matches import _wrap

    for i, img in enumerate((held_out_pair.image0, held_out_pair.image1)):
        grey = img if img.ndim == 2 else cv2.cvtColor(img, cv2.COLOR_RGB2GRAY)
        tint = np.stack([grey, (grey * 0.6).astype(np.uint8), (grey * 0.3).astype(np.uint8)], 2)
        cv2.imwrite(str(tmp_path / f"{i}.png"), tint)  # BGR on disk: a blue-ish image
    K = held_out_pair.K
    assert cli_main(["predict", str(tmp_path / "0.png"), str(tmp_path / "1.png"), "--K",
                     f"{K[0, 0]},{K[1, 1]},{K[0, 2]},{K[1, 2]}", "--png",
                     str(tmp_path / "p.png")]) == 0
    drawn = cv2.imread(str(tmp_path / "p.png"))
    body = drawn[-held_out_pair.image0.shape[0]:]  # below the header band
    b, g, r = (body[..., k].astype(int) for k in range(3))
    assert np.median(b - r) > 20  # the photograph's colour, not grey
    lines = _wrap("green: 512 of 600 point matches support the recommended pose (poselib, "
                  "unreliable); unreliable: a long reason " * 2, 300, 0.45)
    assert len(lines) > 2
    assert all(cv2.getTextSize(t, cv2.FONT_HERSHEY_SIMPLEX, 0.45, 1)[0][0] <= 300
               for t in lines if " " in t)


@pytest.mark.slow
def test_explain_draws_the_importance(pair_files, capsys):
    d, K = pair_files
    code = cli_main(["predict", str(d / "0.png"), str(d / "1.png"), "--K", K, "--json",
                     "--explain", str(d / "why.png"), "--explainer", "attention"])
    cap = capsys.readouterr()
    assert code == 0 and json.loads(cap.out)["pose"]["status"] == "ok"
    assert "explanation ->" in cap.err
    assert cv2.imread(str(d / "why.png")) is not None
    assert cli_main(["predict", str(d / "0.png"), str(d / "1.png"), "--explain",
                     str(d / "why.jpg")]) == 2
    assert "Expected a .png path for --explain" in capsys.readouterr().err
