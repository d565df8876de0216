"""strl_pyg.utils.io.safe_torch_load on a pickle that would run code, and the package's one
version source."""

from __future__ import annotations

import os

import pytest
import torch

from strl_pyg.utils.io import UnsafeFileError, safe_torch_load


class _Evil:
    def __reduce__(self):
        return (os.system, ("echo this must not run",))


def test_a_code_pickle_is_refused_by_name_without_torchs_advice(tmp_path):
    """Before (torch >= 2.6): the user saw torch's 'Weights only load failed ... trusted
    source', which suggests turning safe loading off."""
    path = tmp_path / "evil.pt"
    torch.save({"format": "strl_pyg.StrLPose", "x": _Evil()}, path)
    with pytest.raises(UnsafeFileError) as exc:
        safe_torch_load(path, "StrLPose checkpoint")
    text = str(exc.value)
    assert "would run '" in text and "system'" in text and "nothing was run" in text
    assert "weights_only" not in text and "trusted source" not in text and "\n" not in text


def test_pip_metadata_and_version_are_one_source():
    """Before: `pip show` said 0.3.0 while __version__ was 0.4.0.dev0."""
    import configparser
    from pathlib import Path

    import strl_pyg

    cfg = configparser.ConfigParser()
    cfg.read(Path(__file__).resolve().parents[2] / "setup.cfg")
    assert cfg["metadata"]["version"] == "attr: strl_pyg.__version__"
    from importlib.metadata import version

    assert version("strl-pyg") == strl_pyg.__version__
