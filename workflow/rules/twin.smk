# Digital twin of a Kamech-like catchment (issue 3): truth and observed data for two epochs.
# Twin sites only. The truth goes to twin/truth/ (and twin/epoch2/truth/); only evaluation
# rules may read it. twin/site.json holds what a flight planner knows (extent, CRS, cells).

if IS_TWIN and "twin" in config:
    from kitegully.twin.site import EPOCH2_KEYS as TWIN_EPOCH2_KEYS, EPOCH_KEYS as TWIN_EPOCH_KEYS, PLAN_KEYS as TWIN_PLAN_KEYS

    TWIN_TRUTH = ["dtm.tif", "dsm.tif", "landcover.tif", "landcover_classes.csv", "texture.tif", "targets.csv",
                  "checkpoints.csv", "gully_centrelines.gpkg", "gully_polygons.gpkg", "gully_heads.gpkg"]
    TWIN_OBSERVED = ["gcp_survey.csv", "checkpoints.csv", "field_network.gpkg", "gully_heads.gpkg"]

    def twin_epoch_outputs(prefix):
        out = {f"truth_{n.replace('.', '_')}": result("twin", f"{prefix}truth/{n}") for n in TWIN_TRUTH}
        out.update({f"observed_{n.replace('.', '_')}": result("twin", f"{prefix}observed/{n}") for n in TWIN_OBSERVED})
        return out

    rule twin_site_json:
        output:
            site=result("twin", "site.json"),
        params:
            twin=config_keys("twin", TWIN_PLAN_KEYS),
            crs=config["site"]["crs"],
            seed=config["seed"],
        log:
            logfile("twin", "site_json"),
        script:
            "../scripts/twin_site_json.py"

    rule twin_epoch1:
        output:
            **twin_epoch_outputs(""),
            stats=report(result("twin", "truth/site_statistics.csv"), caption=caption("twin_statistics"), category="2 Twin"),
        params:
            twin=config_keys("twin", TWIN_PLAN_KEYS + TWIN_EPOCH_KEYS),
            crs=config["site"]["crs"],
            seed=config["seed"],
            epoch=1,
        threads: 2
        log:
            logfile("twin", "epoch1"),
        benchmark:
            benchfile("twin", "epoch1")
        script:
            "../scripts/twin_generate.py"

    rule twin_epoch2:
        input:
            targets=result("twin", "truth/targets.csv"),
            checkpoints=result("twin", "truth/checkpoints.csv"),
        output:
            **twin_epoch_outputs("epoch2/"),
            stats=report(result("twin", "epoch2/truth/site_statistics.csv"), caption=caption("twin_statistics_epoch2"), category="2 Twin"),
        params:
            twin=config_keys("twin", TWIN_PLAN_KEYS + TWIN_EPOCH_KEYS + TWIN_EPOCH2_KEYS),
            crs=config["site"]["crs"],
            seed=config["seed"],
            epoch=2,
        threads: 2
        log:
            logfile("twin", "epoch2"),
        benchmark:
            benchfile("twin", "epoch2")
        script:
            "../scripts/twin_generate.py"

    rule twin_figures:
        input:
            dtm=result("twin", "truth/dtm.tif"),
            centrelines=result("twin", "truth/gully_centrelines.gpkg"),
            landcover=result("twin", "truth/landcover.tif"),
            texture=result("twin", "truth/texture.tif"),
            targets=result("twin", "truth/targets.csv"),
            checkpoints=result("twin", "observed/checkpoints.csv"),
            heads=result("twin", "observed/gully_heads.gpkg"),
        output:
            hillshade=report(result("twin", "figures/twin_hillshade_gullies.png"), caption=caption("twin_hillshade_gullies"), category="2 Twin"),
            landcover=report(result("twin", "figures/twin_landcover.png"), caption=caption("twin_landcover"), category="2 Twin"),
            overview=report(result("twin", "figures/twin_site_overview.png"), caption=caption("twin_site_overview"), category="2 Twin"),
        params:
            attribution=config["site"].get("attribution"),
        log:
            logfile("twin", "figures"),
        script:
            "../scripts/twin_figures.py"

    add_targets(
        rules.twin_site_json.output,
        rules.twin_epoch1.output,
        rules.twin_epoch2.output,
        rules.twin_figures.output,
    )


# A DEM twin (issue 16): a terrain with known gullies surveyed as a dense DTM only (no photographs);
# the observed DTM is what the DEM stages read (polygons.dem_file), the truth only evaluation rules.
if IS_TWIN and "dem_twin" in config:

    rule twin_dem:
        output:
            dtm=result("twin", "observed/dtm.tif"),
            truth_dtm=result("twin", "truth/dtm.tif"),
            centrelines=result("twin", "truth/gully_centrelines.gpkg"),
            polygons=result("twin", "truth/gully_polygons.gpkg"),
        params:
            cfg=config["dem_twin"],
            crs=config["site"]["crs"],
            seed=config["seed"],
        log:
            logfile("twin", "dem"),
        script:
            "../scripts/twin_peat_valley.py"
