"""Evaluation of products against survey data and twin truth: error statistics and accuracy tables.

Entry points of the validate stage (docs/architecture.md): :func:`validate_checkpoints`
and :func:`validate_against_truth` with their parameters :class:`CheckpointParams` and
:class:`TruthParams` (all in ``dem``). Imported lazily.
"""

from importlib import import_module

_EXPORTS = {"validate_checkpoints": "dem", "validate_against_truth": "dem", "CheckpointParams": "dem",
            "TruthParams": "dem", "ProfileParams": "dem"}
__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    if name in _EXPORTS:
        return getattr(import_module(f"{__name__}.{_EXPORTS[name]}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
