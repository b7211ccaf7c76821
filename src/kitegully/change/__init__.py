"""Change between epochs (issue 17): co-registration, DEM of difference, uncertainty, budgets.

Modules: ``dod`` (epoch inputs, common grid, DoD), ``coregister`` (Nuth & Kääb shift + plane),
``uncertainty`` (σ per epoch, propagation, GCD thresholds), ``budget`` (volumes by mask,
independent and spatially correlated uncertainty), ``headcuts`` (retreat per digitised head),
``evaluation`` (against known change), ``plots``, ``params`` (:class:`ChangeParams`),
``pipeline`` (:func:`detect_change`, the stage entry point) and ``example`` (inputs of the
DEM-site example).
"""
