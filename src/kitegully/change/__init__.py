"""Change between epochs (issue 17): co-registration, DEM of difference, uncertainty, budgets.

Entry points (docs/architecture.md): :func:`detect_change` with its parameters
:class:`ChangeParams` (both from ``stage``), and :func:`evaluate_change` (``evaluation``,
evaluation only: reads known change). Imported lazily.

Modules: ``stage`` (the stage: files in and out), ``params`` (:class:`ChangeParams`),
``dod`` (epoch inputs and their checks, common grid, DoD), ``coregister`` (Nuth & Kääb
shift + plane on stable ground), ``uncertainty`` (σ per epoch, propagation, GCD
thresholds), ``budget`` (volumes by mask; independent, spatially correlated and
co-registration uncertainty), ``headcuts`` (retreat per digitised head), ``widening`` (width
of each epoch-1 cross-section on both DEMs), ``evaluation`` (against known change), ``plots``
and ``example`` (the synthetic epoch 2 of the controlled check). Cells matched below a stated
correlation are voids (``dod.matching_voids``).
"""

import lazy_loader

__getattr__, __dir__, __all__ = lazy_loader.attach(
    __name__,
    submod_attrs={
        "stage": ["detect_change"],
        "params": ["ChangeParams", "THRESHOLD_METHODS"],
        "evaluation": ["evaluate_change"],
    },
)
