"""Alias of :mod:`strl_pyg.synthetic.match_quality` (match checks on generated pairs), kept
so that old imports work; not to be confused with :mod:`strl_pyg.metrics.two_view` (pose errors)."""

from strl_pyg.synthetic.match_quality import *  # noqa: F403
from strl_pyg.synthetic.match_quality import __all__  # noqa: F401
