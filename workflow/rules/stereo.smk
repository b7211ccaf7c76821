# Plot-scale stereo (issue 19, Moritani et al. 2010) on a stereo-rig twin: its own site
# (config/sites/stereo_lab.yaml, `make stereo`), not part of the default run. One rule per run:
# calibration (+ calibration test) -> dry box, rain, wind, each processed with the calibrated
# cameras. Each rule renders its photographs (twin step) and processes them with observed
# quantities only; the reference it scores against is the paper's (point gauge, gravimetric depth).

if "stereo" in config:

    STEREO = config["stereo"]
    STEREO_CAT = "Plot-scale stereo (Moritani et al. 2010)"

    rule stereo_calibrate:
        """Table 1 regenerated, the calibration test (H 2-6 m, B 1 m) and the calibrated cameras."""
        output:
            calibration=report(result("stereo", "calibration.csv"), caption=caption("stereo_calibration"), category=STEREO_CAT),
            cameras=result("stereo", "cameras.json"),
            test=result("stereo", "calibration_test.csv"),
            test_png=report(result("stereo", "calibration_test.png"), caption=caption("stereo_calibration_test"), category=STEREO_CAT),
        params:
            stereo={k: STEREO[k] for k in ("calibration", "calibration_test")},
            seed=config["seed"],
        log:
            logfile("stereo", "calibrate"),
        benchmark:
            benchfile("stereo", "calibrate")
        threads: 1
        script:
            "../scripts/stereo_calibrate.py"

    rule stereo_dry_box:
        """11 set-ups (MAE vs L) and 16 removals at L = 9.1 m (A = b*M)."""
        input:
            cameras=rules.stereo_calibrate.output.cameras,
        output:
            mae_vs_L=report(result("stereo", "mae_vs_L.csv"), caption=caption("stereo_mae_vs_L"), category=STEREO_CAT),
            mae_vs_L_png=report(result("stereo", "mae_vs_L.png"), caption=caption("stereo_mae_vs_L"), category=STEREO_CAT),
            removals=report(result("stereo", "removals.csv"), caption=caption("stereo_removals"), category=STEREO_CAT),
            removals_png=report(result("stereo", "removals.png"), caption=caption("stereo_removals"), category=STEREO_CAT),
            dod_png=report(result("stereo", "dod_dry_box.png"), caption=caption("stereo_dod"), category=STEREO_CAT),
        params:
            stereo={k: STEREO[k] for k in ("processing", "dry_box")},
            seed=config["seed"],
        log:
            logfile("stereo", "dry_box"),
        benchmark:
            benchfile("stereo", "dry_box")
        threads: 1
        script:
            "../scripts/stereo_dry_box.py"

    rule stereo_rain:
        """Three bulk densities under 60 mm/h for 1 h on 10 degrees."""
        input:
            cameras=rules.stereo_calibrate.output.cameras,
        output:
            rain_runs=report(result("stereo", "rain_runs.csv"), caption=caption("stereo_rain"), category=STEREO_CAT),
            rain_series=result("stereo", "rain_series.csv"),
            **{f"dod_png_{i}": report(result("stereo", f"dod_rain_{i + 1}.png"), caption=caption("stereo_dod"), category=STEREO_CAT)
               for i in range(len(STEREO["rain"]["bulk_densities"]))},
        params:
            stereo={k: STEREO[k] for k in ("processing", "rain")},
            seed=config["seed"],
        log:
            logfile("stereo", "rain"),
        benchmark:
            benchfile("stereo", "rain")
        threads: 1
        script:
            "../scripts/stereo_rain.py"

    rule stereo_wind:
        """Wind tunnel: sand tray before and after 45 min at 4.5 m/s."""
        input:
            cameras=rules.stereo_calibrate.output.cameras,
        output:
            wind_run=report(result("stereo", "wind_run.csv"), caption=caption("stereo_wind"), category=STEREO_CAT),
            dod_png=report(result("stereo", "dod_wind.png"), caption=caption("stereo_dod"), category=STEREO_CAT),
        params:
            stereo={k: STEREO[k] for k in ("processing", "wind")},
            seed=config["seed"],
        log:
            logfile("stereo", "wind"),
        benchmark:
            benchfile("stereo", "wind")
        threads: 1
        script:
            "../scripts/stereo_wind.py"

    add_targets(rules.stereo_calibrate.output, rules.stereo_dry_box.output, rules.stereo_rain.output, rules.stereo_wind.output)
