# Products that open everywhere (issue 14): a QGIS project of the site's products,
# results/<site>/<site>.qgs, written as plain XML (no QGIS needed). Its inputs are only the
# products the site's other rules make (a rule file that does not apply leaves its layer out).
# Rules of the survey chain run per epoch ({epoch}); the project shows epoch 1, the site's
# first survey (its paths are those of a one-epoch site).

_DEFINED_RULES = {r.name for r in workflow.rules}


def _qgis_products():
    """Product key -> path of every map product the site's rules make (epoch 1, then epoch 2)."""
    out = {}

    def add(key, rule, name, n=1):
        if rule in _DEFINED_RULES:
            out[key] = expand(getattr(getattr(rules, rule).output, name), epoch=epoch_dir(n))[0]

    dsm_rule = globals().get("DENSE_DSM_RULE", "dense_match")  # tiled sites (issue 21): dense_merge / dense_finish
    ortho_rule = globals().get("DENSE_ORTHO_RULE", "dense_match")
    add("dsm", dsm_rule, "dsm")
    add("orthophoto", ortho_rule, "orthophoto")
    add("gully_network", "gully_map", "network")
    add("gully_polygons", "gully_map", "polygons")
    if "obia" in config and config["obia"]["kite_scale"]["enabled"]:
        add("bare_soil", "obia_kite_scale", "bare_soil")
        add("bare_soil_polygons", "obia_kite_scale", "polygons")
    add("checkpoint_errors", "validate_checkpoints", "errors")
    # further products, unticked in the project: every other map the stages write
    add("gully_depth", "gully_map", "depth")
    for n in SURVEY_EPOCHS:
        sfx = "" if n == 1 else f"_epoch{n}"
        if n != 1:
            add(f"dsm{sfx}", dsm_rule, "dsm", n)
            add(f"orthophoto{sfx}", ortho_rule, "orthophoto", n)
        add(f"camera_positions{sfx}", "georef_adjust", "cameras", n)
        add(f"sparse_cloud{sfx}", "georef_adjust", "cloud", n)
    if "polygons_map" in _DEFINED_RULES:
        for path in rules.polygons_map.output.polygons:
            out["hoefle_polygons_t" + Path(path).stem.removeprefix("gully_polygons_t")] = path
        for key, name in (("hoefle_dem", "dem"), ("tci", "tci"), ("fill_depth", "fill_depth"), ("breaklines", "breaklines"),
                          ("thalweg", "thalweg"), ("transects", "transects")):
            add(key, "polygons_map", name)
        morph_rule = globals().get("POLY_MORPH_RULE", "polygons_map")  # tiled sites (issue 21): polygons_morph_merge
        add("medial_axes", morph_rule, "axes")
        add("cross_sections", morph_rule, "sections")
    if "change_detect" in _DEFINED_RULES:
        for key, name in (("dod", "dod"), ("sigma_dod", "sigma_dod"), ("stable_ground", "stable")):
            add(key, "change_detect", name)
        for name in rules.change_detect.output.keys():
            if name.startswith("thresholded_"):
                add("dod_" + name, "change_detect", name)
    return out


_QGIS_PRODUCTS = _qgis_products()

if _QGIS_PRODUCTS:

    rule report_qgis:
        """QGIS project of the site's products (DSM + hillshade, orthophoto, gullies, bare soil, checkpoint errors)."""
        input:
            **_QGIS_PRODUCTS,
        output:
            project=str(RESULTS / f"{SITE}.qgs"),
            **({"checkpoints": result("report", "checkpoint_errors.gpkg")} if "checkpoint_errors" in _QGIS_PRODUCTS else {}),
        params:
            site=SITE,
            crs=config["site"]["crs"],
            error_limit_m=config["validate"]["error_limit_m"] if "validate" in config else 0.5,
            shading=config["dense"]["shading"] if "dense" in config else {"azimuth_deg": 315.0, "altitude_deg": 45.0},
        log:
            logfile("report", "qgis"),
        script:
            "../scripts/report_qgis.py"

    add_targets(str(RESULTS / f"{SITE}.qgs"))
