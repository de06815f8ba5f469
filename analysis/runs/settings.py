"""Tunable choices of the analysis and their defaults (imported by summary and traffic_run)."""
from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

from analysis.metrics import comfort, formation, traffic

__all__ = ["AnalysisSettings", "DEFAULT_SETTINGS", "settings_dict"]


@dataclass(frozen=True, slots=True)
class AnalysisSettings:
    """Tunable choices of the analysis (all required; see :data:`DEFAULT_SETTINGS`)."""

    settle_tol_m: float  # m, settling band on the error norm
    jerk_window_s: float  # s, Savitzky-Golay window span
    jerk_polyorder: int  # -, Savitzky-Golay polynomial order
    column_dy_tol_m: float  # m, same-column tolerance on the lateral offset
    interaction_range_m: float  # m, pairs farther apart are not evaluated; "near" window
    clearance_threshold_m: float  # m, time with outline clearance below it
    lateral_gap_threshold_m: float  # m, time with side-by-side lateral gap below it
    ttc2d_threshold_s: float  # s, time with 2-D TTC below it
    ttc2d_horizon_s: float  # s, constant-velocity extrapolation horizon of the 2-D TTC
    headway_threshold_s: float  # s, time with time headway below it
    ssm_ttc_warning_s: float  # s, SSM conflicts counted with min TTC below it
    ssm_ttc_critical_s: float  # s, SSM conflicts counted as critical below it
    ssm_drac_high_mps2: float  # m/s^2, SSM conflicts counted with max DRAC above it
    baseline_min_length_m: float  # m, shortest common section timed against the baseline
    anim_duration_s: float  # s, length of the bird's-eye animation
    anim_fps: float  # 1/s, frames per second of the animation (and per simulated second)
    anim_start_s: float | None  # s, first animated instant; None: around the closest approach


DEFAULT_SETTINGS = AnalysisSettings(
    settle_tol_m=formation.SETTLING_TOLERANCE_M,
    jerk_window_s=comfort.JERK_WINDOW_S,
    jerk_polyorder=comfort.JERK_POLYORDER,
    column_dy_tol_m=formation.COLUMN_DY_TOLERANCE_M,
    interaction_range_m=traffic.INTERACTION_RANGE_M,
    clearance_threshold_m=traffic.CLEARANCE_THRESHOLD_M,
    lateral_gap_threshold_m=traffic.LATERAL_GAP_THRESHOLD_M,
    ttc2d_threshold_s=traffic.TTC2D_THRESHOLD_S,
    ttc2d_horizon_s=traffic.TTC2D_HORIZON_S,
    headway_threshold_s=traffic.HEADWAY_THRESHOLD_S,
    ssm_ttc_warning_s=traffic.SSM_TTC_WARNING_S,
    ssm_ttc_critical_s=traffic.SSM_TTC_CRITICAL_S,
    ssm_drac_high_mps2=traffic.SSM_DRAC_HIGH_MPS2,
    baseline_min_length_m=50.0,
    anim_duration_s=30.0,
    anim_fps=5.0,
    anim_start_s=None,
)


def settings_dict(settings: AnalysisSettings) -> dict[str, Any]:
    """Settings as a plain dict, for JSON.

    Parameters
    ----------
    settings : AnalysisSettings
        Settings to convert.

    Returns
    -------
    dict
        Field name to value.
    """
    return asdict(settings)
