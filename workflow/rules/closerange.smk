# Stage closerange: Mayr et al. 2016's photogrammetric half (paper 001 sect. 2.2 steps 1-2, Table 1).
#
# Per OBIA scene (twin sites): pole-camera photos of the scene (twin side) -> SfM with
# self-calibration (the sfm stage's library) -> sphere centres measured in the photos,
# triangulated and fitted to the sphere survey (similarity) -> pairwise SGM dense points ->
# 2 cm trimmed-mean DEM and orthophoto cropped by the camera circle -> the obia stage's
# classification and evaluation on these orthophotos -> Table 1 and the accuracy next to the
# direct renders' and the paper's. The default run builds closerange.scenes (one scene);
# `make closerange` sets closerange.scenes to all and closerange.on_scene_failure to record:
# closerange_sfm is then a checkpoint whose record says whether the scene was georeferenced;
# the summary reads the records and asks for the classification / evaluation of the scenes
# that succeeded only, and lists the failed ones with their sentence.

import json

if "closerange" in config and "obia" in config and IS_TWIN:

    CR = config["closerange"]
    CR_SCENES = OBIA_SCENES if CR["scenes"] == "all" else list(CR["scenes"])
    _cr_unknown = sorted(set(CR_SCENES) - set(OBIA_SCENES))
    if _cr_unknown:
        raise WorkflowError(f"Invalid configuration: closerange.scenes names {', '.join(_cr_unknown)}, not among the obia scenes ({OBIA_SCENES[0]} .. {OBIA_SCENES[-1]})")
    # what closerange_sfm reads (CloseRangeParams); the walk belongs to the photos rule
    CR_SFM_KEYS = ("spheres", "sfm_max_num_features", "sfm_affine_features", "sphere_tolerance_m", "marker_budget_m", "dense", "trim", "periphery",
                   "fill_holes_cells", "outlier_cell_m", "outlier_tolerance_m", "min_dense_points",
                   "rule_paint_rgb", "rule_min_paint_fraction", "rule_strip_width_m", "on_scene_failure")
    CR_ON_FAILURE = CR.get("on_scene_failure", "stop")


    def _cr(name):
        return result("closerange", "scenes/{scene}/" + name)


    rule closerange_photos:
        """Pole-camera photos of one scene (twin side: the scene's truth builds the photographed world)."""
        input:
            orthophoto=_obia_scene("orthophoto.tif"),
            dem=_obia_scene("dem.tif"),
            markers=_obia_scene("markers.csv"),
            truth_eroded=_obia_scene("truth/eroded.tif"),
            truth_markers=_obia_scene("truth/markers.tif"),
            truth_meta=_obia_scene("truth/scene.json"),
        output:
            photos=directory(_cr("photos")),
            truth=_cr("truth/walk.json"),
        params:
            walk=CR["walk"],
            no_rule=CR["scenes_without_rule"],
            sphere_radius_m=OBIA["scenes"]["marker_radius_m"],
            seed=config["seed"],
        log:
            logfile("closerange", "photos_{scene}"),
        benchmark:
            benchfile("closerange", "photos_{scene}")
        threads: 2
        script:
            "../scripts/closerange_photos.py"


    checkpoint closerange_sfm:
        """SfM, spheres as GCPs (similarity), dense points, 2 cm DEM and orthophoto, folding-rule legs (photos and survey only).

        A checkpoint: with on_scene_failure: record its record may say ``failed`` (the summary then skips the scene)."""
        input:
            photos=_cr("photos"),
            markers=_obia_scene("markers.csv"),
            frame=_obia_scene("dem.tif"),
        output:
            model=directory(_cr("model")),
            work=temp(directory(_cr("sfm_work"))),
            summary=_cr("sfm_summary.json"),
            images=_cr("sfm_images.csv"),
            image_info=_cr("image_info.json"),
            orthophoto=_cr("orthophoto.tif"),
            dem=_cr("dem.tif"),
            spheres=_cr("sphere_residuals.csv"),
            record=_cr("closerange.json"),
        params:
            closerange=dict({k: CR[k] for k in CR_SFM_KEYS if k in CR}, pole_height_m=CR["walk"].get("pole_height_m", 3.0),
                            sphere_radius_m=OBIA["scenes"]["marker_radius_m"]),
            sfm=config["sfm"],
            seed=config["seed"],
        log:
            logfile("closerange", "sfm_{scene}"),
        benchmark:
            benchfile("closerange", "sfm_{scene}")
        threads: 2
        script:
            "../scripts/closerange_sfm.py"


    use rule obia_classify as closerange_classify with:
        input:
            orthophoto=_cr("orthophoto.tif"),
            dem=_cr("dem.tif"),
            markers=_obia_scene("markers.csv"),
        output:
            segments=_cr("segments.tif"),
            exg=_cr("exg_blurred.tif"),
            classification=_cr("classification.tif"),
            classification_otsu=_cr("classification_otsu.tif"),
            polygons=_cr("eroded_areas.gpkg"),
            histogram=_cr("exg_histogram.csv"),
            info=_cr("threshold.json"),
        log:
            logfile("closerange", "classify_{scene}"),
        benchmark:
            benchfile("closerange", "classify_{scene}")


    use rule obia_evaluate as closerange_evaluate with:
        input:
            orthophoto=_cr("orthophoto.tif"),
            segments=_cr("segments.tif"),
            classification=_cr("classification.tif"),
            classification_otsu=_cr("classification_otsu.tif"),
            histogram=_cr("exg_histogram.csv"),
            info=_cr("threshold.json"),
            truth_eroded=_obia_scene("truth/eroded.tif"),
        output:
            confusion=_cr("confusion.json"),
            figure=report(
                _cr("scene_figure.png"),
                caption=caption("closerange_scene"),
                category="Bare soil (OBIA)",
                subcategory="Close-range SfM scenes",
                labels={"scene": "{scene}"},
            ),
        log:
            logfile("closerange", "evaluate_{scene}"),


    def _cr_succeeded(wildcards):
        """Scenes whose SfM georeferenced them: all with on_scene_failure: stop (a failure stops the run),
        else read from the checkpoints' records (the records are static inputs, so all scenes run at once)."""
        if CR_ON_FAILURE == "stop":
            return CR_SCENES
        ok = []
        for s in CR_SCENES:
            with open(checkpoints.closerange_sfm.get(scene=s).output.record, encoding="utf-8") as fh:
                if json.load(fh).get("status", "ok") == "ok":
                    ok.append(s)
        return ok


    def _cr_each(pattern):
        return lambda wildcards: expand(pattern, scene=_cr_succeeded(wildcards))


    rule closerange_summary:
        """Table 1 (001) next to the paper's; OBIA accuracy on the photogrammetric vs direct orthophotos (evaluation)."""
        input:
            records=expand(_cr("closerange.json"), scene=CR_SCENES),
            confusion_sfm=_cr_each(_cr("confusion.json")),
            confusion_direct=_cr_each(_obia_scene("confusion.json")),
            class_direct=_cr_each(_obia_scene("classification.tif")),
            class_sfm=_cr_each(_cr("classification.tif")),
            truth=_cr_each(_obia_scene("truth/eroded.tif")),
        output:
            table1=report(result("obia", "closerange_sfm.csv"), caption=caption("closerange_table1"), category="Bare soil (OBIA)", subcategory="Close-range SfM scenes"),
            table1_md=result("obia", "closerange_sfm.md"),
            accuracy=report(result("obia", "closerange_accuracy.csv"), caption=caption("closerange_accuracy"), category="Bare soil (OBIA)", subcategory="Close-range SfM scenes"),
            accuracy_md=result("obia", "closerange_accuracy.md"),
        log:
            logfile("closerange", "summary"),
        script:
            "../scripts/closerange_summary.py"


    if CR_SCENES:
        add_targets(
            result("obia", "closerange_sfm.csv"),
            result("obia", "closerange_accuracy.csv"),
            # record mode: the figures of the scenes that succeeded come with the summary's evaluations
            *(expand(_cr("scene_figure.png"), scene=CR_SCENES) if CR_ON_FAILURE == "stop" else []),
        )
