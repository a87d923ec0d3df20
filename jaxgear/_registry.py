"""Imports every module that defines a result type, so the codec knows them all."""

from .analysis import _result  # noqa: F401
from .continuation import _branch  # noqa: F401
from .design import _design  # noqa: F401
from .shooting import _search  # noqa: F401
from .sweep import _basins, _bifurcation, _parameter_map  # noqa: F401
