"""Evaluation of products against survey data and twin truth: error statistics and accuracy tables.

Entry points of the validate stage (docs/architecture.md): :func:`validate_checkpoints`
and :func:`validate_against_truth` with their parameters :class:`CheckpointParams` and
:class:`TruthParams` (all in ``dem``). Imported lazily.
"""

import lazy_loader

__getattr__, __dir__, __all__ = lazy_loader.attach(
    __name__,
    submod_attrs={
        "dem": [
            "validate_checkpoints", "validate_against_truth", "CheckpointParams", "TruthParams",
            "ProfileParams",
        ],
    },
)
