"""The metrics a sweep summarises per case (``summary.parquet``, formation_traci/sweep/row.py
fills them) and the paired effects of a sweep with twins: defined with the analysis that
computes them, so the sweep imports the analysis and never the other way round."""
from __future__ import annotations

from analysis.runs.section_measures import DRAC_MPS2, SECTION_METRICS, TTC_S  # noqa: F401 (re-exported)

METRICS: dict[str, tuple[str, str]] = {
    # name: (unit, meaning) -- "max" is the largest value over the members
    "e_rms_m": ("m", "max of each member's r.m.s. formation error |e| over the whole run (eq 2.5)"),
    "e_max_settled_m": ("m", "max of each member's peak |e| after it settled; NaN if one never settles"),
    "e_rms_settled_m": ("m", "r.m.s. over members of each member's settled r.m.s. |e|; NaN if one never settles"),
    "settling_time_s": ("s", "max settling time into the 0.2 m band; NaN if one never settles"),
    "n_unsettled": ("-", "members that never settle into the 0.2 m band"),
    "a_lat_peak_mps2": ("m/s^2", "max peak |a_lat|"),
    "jerk_lat_rms_mps3": ("m/s^3", "max r.m.s. lateral jerk"),
    "jerk_lon_rms_mps3": ("m/s^3", "max r.m.s. longitudinal jerk"),
    "t_lat_above_comfort_s": ("s", "max time with |a_lat| > 1.8 m/s^2 (medium, uncomfortable and beyond bands)"),
    "t_lon_above_comfort_s": ("s", "max time with |a_lon| > 2 m/s^2"),
    "slip_over_s": ("s", "max time over the tire slip limit (dynamic model; NaN for kinematic)"),
    "traction_over_s": ("s", "max time over the traction limit (dynamic model; NaN for kinematic)"),
    "friction_over_s": ("s", "max time outside the friction circle"),
    "member_collisions": ("-", "run.json incidents: member collisions (our body clearance < 0, or a SUMO collision with a SUMO vehicle our clearance confirms; one per pair and contact)"),
    "member_removed": ("-", "run.json incidents: members SUMO no longer has or that were taken out"),
    "stranded": ("-", "run.json incidents: members standing (< 0.5 m/s for > 5 s) while their v_ref is above 2 m/s"),
    "sumo_collision_artefacts": ("-", "run.json incidents: SUMO collision reports of a member our clearance refutes (not in the verdict)"),
    "collisions": ("-", "SUMO runs: collision events involving a member (SUMO's reports our clearance does not refute; NaN in free space)"),
    "min_ttc_s": ("s", "SUMO runs: smallest SSM time to collision of a conflict involving a member"),
    "emergency_brakes": ("-", "SUMO runs: emergency_brake events (the virtual car or a member braking harder than comfortable)"),
    "requested_veh": ("-", "SUMO runs: vehicles the flows asked for up to the run's end (warm-up included)"),
    "inserted_veh": ("-", "SUMO runs: vehicles SUMO inserted for the flows"),
    "flow_measured_veh_h": ("veh/h", "SUMO runs: flow over all lanes at traffic.measure_at during the formation's run"),
    "density_measured_veh_km": ("veh/km", "SUMO runs: density over all lanes at traffic.measure_at during the formation's run"),
    "energy_kwh_per_100km": ("kWh/100km", "all members' traction energy over their distance (docs/energy.md)"),
    "energy_saving_vs_alone": ("-", "1 - members' energy / their energy alone; NaN with resistances off"),
    "leader_age_mean_s": ("s", "max of each member's mean age of the virtual-car state it held ([comm])"),
    "leader_age_p95_s": ("s", "max of each member's 95th percentile of that age"),
    "formation_shortfall": ("-", "SUMO runs with formation flows: share of the formations due within the run that did not enter (1 - inserted / requested over every flow; a formation_shortfall event below 95 % inserted)"),
    "comm_timeouts": ("-", "SUMO runs: comm_timeout events (a member fell back: no state for longer than comm.timeout_s)"),
    **SECTION_METRICS,
    "min_gap_m": ("m", "smallest bumper-to-bumper gap between consecutive members of a column over the run (metrics.json formations min_gap_m; negative: bodies overlap)"),
    "ramp_vehicles": ("-", "SUMO runs with on-ramps: ramp vehicles that reached their merge within the horizon while a formation was near (run.json merges, over the formations)"),
    "ramp_merged_before_lane_end": ("-", "those that did not stand at the end of the acceleration lane"),
    "ramp_speed_loss_mps": ("m/s", "their mean speed loss: first speed seen less the lowest before merging"),
    "ramp_wait_s": ("s", "their mean time below 1 m/s on the ramp's lanes"),
    "law_fallbacks": ("-", "law_fallback events (a CACC member's beacons timed out: it ran ACC, controller.fallback_acc)"),
    "stretch_coverage": ("-", "with twins: share of the background vehicles in the measured stretch timed over all of it in both runs"),
    "matched_share": ("-", "with twins: share of those vehicles matched by id in the other run"),
    **{f"fx_{k}": (u, f"with twins: formation run minus its twin, {m}") for k, (u, m) in {
        "delay_mean_s": ("s", "mean stretch travel-time delay of the timed vehicles"),
        "delay_total_s": ("s", "summed stretch travel-time delay of the timed vehicles [veh*s]"),
        "exit_delay_total_s": ("s", "summed later arrival of the timed vehicles at the last section [veh*s]"),
        "speed_mps": ("m/s", "space-mean speed of the timed vehicles over the stretch"),
        "spot_speed_mps": ("m/s", "mean speed of the timed vehicles at the sections"),
        "spot_speed_var_m2ps2": ("m^2/s^2", "variance of those speeds"),
        "throughput_veh_h": ("veh/h", "vehicles over the downstream section during the run"),
        "lane_changes": ("-", "lane changes of the timed vehicles in the stretch"),
        "conflicts": ("-", "passages of the timed vehicles with a TTC below 3 s at a section"),
    }.items()},
}
"""Metric columns of ``summary.parquet``: unit and meaning."""

EFFECT_KEYS: dict[str, str] = {
    "fx_delay_mean_s": "twin_delay_mean_s", "fx_delay_total_s": "twin_delay_total_s",
    "fx_exit_delay_total_s": "twin_exit_delay_total_s", "fx_speed_mps": "twin_speed_delta_mps",
    "fx_spot_speed_mps": "twin_spot_speed_delta_mps",
    "fx_spot_speed_var_m2ps2": "twin_spot_speed_var_delta_m2ps2",
    "fx_throughput_veh_h": "twin_throughput_delta_veh_h", "fx_lane_changes": "twin_lane_changes_delta",
    "fx_conflicts": "twin_conflicts_delta",
}
"""Paired summary columns -> the analysis' ``traffic.run`` key (analysis/runs/twin_sections.py)."""
