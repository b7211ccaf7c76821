# Kite line model, observed flight angles and flight plan (Feurer et al. 2018 sect. 2.2-2.3).

from kitegully.tether.config import check_tether_config
from kitegully.tether.stage import PLAN_KEYS as _TETHER_PLAN_KEYS, SIMULATION_KEYS as _TETHER_SIMULATION_KEYS

if "tether" in config:

    TETHER = config["tether"]
    try:
        check_tether_config(TETHER)
    except InputError as _err:
        raise WorkflowError(f"Invalid configuration: {_err}") from None
    TETHER_FLIGHTS = [f["name"] for f in TETHER["observed"]["flights"]]

    def tether_keys(*keys):
        """The ``tether:`` keys a rule reads, and only those (the params rerun trigger)."""
        return {k: TETHER[k] for k in keys}

    # line model: materials, kites, atmosphere, discretisation (read by every tether rule)
    TETHER_MODEL_KEYS = ("lines", "kites", "kite_model", "atmosphere", "segment_length_m")

    rule tether_simulation:
        output:
            table=result("tether", "flight_angles.csv"),
            shapes=report(result("tether", "line_shapes.png"), caption=caption("tether_line_shapes"), category="1 Tether"),
            angles=report(
                result("tether", "flight_angle_vs_length.png"),
                caption=caption("tether_flight_angle"),
                category="1 Tether",
            ),
            table2=report(result("tether", "table2_comparison.csv"), caption=caption("tether_table2"), category="1 Tether"),
        params:
            tether=tether_keys(*_TETHER_SIMULATION_KEYS),
        log:
            logfile("tether", "simulation"),
        script:
            "../scripts/tether_simulation.py"

    rule tether_plan:
        output:
            plan=report(result("tether", "flight_plan.csv"), caption=caption("tether_plan"), category="1 Tether"),
            lengths=report(
                result("tether", "line_lengths_for_heights.csv"),
                caption=caption("tether_line_lengths"),
                category="1 Tether",
            ),
        params:
            tether=tether_keys(*_TETHER_PLAN_KEYS),
        log:
            logfile("tether", "plan"),
        script:
            "../scripts/tether_plan.py"

    if TETHER["observed"]["source"] == "synthetic":

        rule tether_synthetic_logs:
            output:
                camera=expand(result("tether", "gps_logs/{flight}_camera.gpx"), flight=TETHER_FLIGHTS),
                operator=expand(result("tether", "gps_logs/{flight}_operator.gpx"), flight=TETHER_FLIGHTS),
            params:
                cfg=tether_keys(*TETHER_MODEL_KEYS, "observed"),
                crs=config["site"]["crs"],
                seed=config["seed"],
            log:
                logfile("tether", "synthetic_logs"),
            script:
                "../scripts/tether_synthetic_logs.py"

        TETHER_CAMERA_LOGS = rules.tether_synthetic_logs.output.camera
        TETHER_OPERATOR_LOGS = rules.tether_synthetic_logs.output.operator
    else:
        TETHER_CAMERA_LOGS = [f["camera_log"] for f in TETHER["observed"]["flights"]]
        TETHER_OPERATOR_LOGS = [f["operator_log"] for f in TETHER["observed"]["flights"]]

    rule tether_observed_angles:
        input:
            camera=TETHER_CAMERA_LOGS,
            operator=TETHER_OPERATOR_LOGS,
        output:
            fixes=result("tether", "observed_flight_angles_fixes.csv"),
            summary=report(
                result("tether", "observed_flight_angles.csv"),
                caption=caption("tether_observed_table"),
                category="1 Tether",
            ),
            figure=report(
                result("tether", "observed_flight_angles.png"),
                caption=caption("tether_observed"),
                category="1 Tether",
            ),
        params:
            cfg=tether_keys(*TETHER_MODEL_KEYS, "observed", "simulation_kite", "sweep"),
            crs=config["site"]["crs"],
        log:
            logfile("tether", "observed_angles"),
        script:
            "../scripts/tether_observed_angles.py"

    add_targets(
        *rules.tether_simulation.output,
        *rules.tether_plan.output,
        *rules.tether_observed_angles.output,
    )
