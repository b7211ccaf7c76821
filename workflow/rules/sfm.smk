# Structure from motion with pycolmap (issue 5): prepared images, SIFT, matching, incremental
# mapping with one shared self-calibrated camera. Real sites read config["inputs"]; twin
# sites read the rendered photos of the flight stage.

if "sfm" in config:

    def sfm_images_dir(wildcards=None):
        """Folder of the photographs: config inputs for real sites, flight outputs for twins."""
        if IS_TWIN:
            return eresult("flight", "observed/images")
        return config["inputs"]["images_dir"]

    def sfm_camera_log():
        """Camera GPS log for spatial matching: [] (none), the twin flight's logger, or a path."""
        log = config["sfm"]["matching"]["camera_log"]
        if log is None:
            return []
        if log == "flight":
            if not IS_TWIN:
                raise WorkflowError("sfm.matching.camera_log: 'flight' is only valid on twin sites")
            return [eresult("flight", "observed/camera_gps.gpx")]
        return [log]

    rule sfm_reconstruct:
        input:
            images=sfm_images_dir(),
            camera_log=sfm_camera_log(),
            checked=eresult("inputs", "report.json"),
        output:
            work=directory(eresult("sfm", "work")),
            model=directory(eresult("sfm", "model")),
            summary=report(eresult("sfm", "summary.json"), caption=caption("sfm_summary"), category="Structure from motion"),
            images_csv=report(eresult("sfm", "images.csv"), caption=caption("sfm_images"), category="Structure from motion"),
            image_info=eresult("sfm", "image_info.json"),
        params:
            sfm=config["sfm"],
            seed=config["seed"],
            crs=config["site"]["crs"],
        threads: 1 if config["sfm"]["deterministic"] else config["sfm"]["threads"]  # deterministic: one thread
        log:
            elogfile("sfm", "sfm_reconstruct"),
        benchmark:
            ebenchfile("sfm", "sfm_reconstruct")
        script:
            "../scripts/sfm_reconstruct.py"

    add_targets(epoch_results("sfm", "summary.json"))
