"""Plain-text before/after tables for ``fieldbank whatif``."""

from __future__ import annotations

import math

from fieldbank.evaluate.compare import Comparison
from fieldbank.evaluate.probing import JointStretch
from fieldbank.evaluate.severity import ComponentGrade
from fieldbank.interventions.course import TimeCourse
from fieldbank.interventions.defaults import DOSE_UNIT
from fieldbank.interventions.inverse import DoseSplitResult
from fieldbank.interventions.plan import Plan


def _pct(before: float, after: float) -> str:
    if abs(before) < 1e-12:
        return "" if abs(after) < 1e-12 else "   (new)"
    return f"{100.0 * (after - before) / before:+7.1f}%"


def _deg(rad: float) -> str:
    return f"{math.degrees(rad):6.0f}°"


def _angle(deg: float | None) -> str:
    return "—" if deg is None else f"{deg:.0f}"


def _stretch_lines(c: Comparison) -> list[str]:
    """Per joint and direction: slow and fast resisting torque, velocity-dependent part, catch."""
    first: JointStretch = c.before.stretches[0]
    slow = f"slow {first.slow_speed_deg_s:.0f}°/s N·m"
    fast = f"fast {first.speed_deg_s:.0f}°/s N·m"
    out = [f"  {'Joint stretch':<20}{slow:<17}{fast:<25}{'velocity-dependent N·m':<25}"
           f"{'catch at':>8}{'R1 °':>11}{'R2 °':>12}{'R2−R1 °':>12}"]
    for name, b, a in c.stretch_rows():
        out.append(
            f"  {name:<20}{b.slow_torque_n_m:5.2f} → {a.slow_torque_n_m:<6.2f}   "
            f"{b.peak_torque_n_m:5.2f} → {a.peak_torque_n_m:<6.2f}"
            f"{_pct(b.peak_torque_n_m, a.peak_torque_n_m):>8}   "
            f"{b.reflex_torque_n_m:5.2f} → {a.reflex_torque_n_m:<6.2f}"
            f"{_pct(b.reflex_torque_n_m, a.reflex_torque_n_m):>8}   "
            f"{b.catch_threshold_n_m:5.2f} N·m"
            f"{_angle(b.catch_angle_deg):>5} → {_angle(a.catch_angle_deg):<4}"
            f"{_angle(b.slow_stop_angle_deg):>5} → {_angle(a.slow_stop_angle_deg):<4}"
            f"{b.dynamic_range_deg:5.0f} → {a.dynamic_range_deg:<4.0f}")
    out.append("  Tardieu-style catch: R1 where the fast stretch, R2 where the slow one first "
               "meets twice the unimpaired arm's largest slow-stretch torque (— never within the "
               "range); R2−R1 is the velocity-dependent part. Angles: elbow 0° straight, "
               "shoulder from +x, flexion positive.")
    return out


def _grade_cell(b: ComponentGrade, a: ComponentGrade) -> str:
    return f"{b.text()} → {a.text()} ({b.score:.1f} → {a.score:.1f})"


def _severity_lines(c: Comparison) -> list[str]:
    """Per muscle group: passive and dynamic grade before → after (score 0 … 4)."""
    out = [f"  {'Severity':<29}{'graded on':<19}{'passive (contracture)':<36}"
           "dynamic (spasticity)",
           f"  {'':<29}{'':<19}{'before → after (score)':<36}before → after (score)"]
    for g, sb, sa in c.severity_rows():
        out.append(f"  {f'{sb.name} ({g})':<29}{sb.stretch:<19}"
                   f"{_grade_cell(sb.passive, sa.passive):<36}"
                   f"{_grade_cell(sb.dynamic, sa.dynamic)}")
    flagged = sorted({n for _, sb, _ in c.severity_rows() for k in ("passive", "dynamic")
                      for n in sb.component(k).unidentified})
    out.append("  score 0 unimpaired … 4 severe; + beyond severe; * rests on a parameter the "
               "fit did not identify" + (f" ({', '.join(flagged)})" if flagged else ""))
    return out


def render_text(source: str, plan: Plan, c: Comparison, course: TimeCourse | None = None,
                inverse: DoseSplitResult | None = None,
                warnings: tuple[str, ...] = ()) -> str:
    out: list[str] = []
    w = out.append
    w(f"Model:  {source}")
    w("Plan:")
    out.extend(f"  {line}" for line in plan.describe())
    out.extend(f"Warning: {msg}." for msg in warnings)
    w("Model predictions, not treatment advice.")
    if inverse is not None:
        w("")
        w("Inverse what-if (botulinum split under a total of "
          f"{inverse.total_units_limit:g} U, week {inverse.weeks_since:g}; {DOSE_UNIT}):")
        w("  " + ", ".join(f"{g} {u:g} U" for g, u in inverse.units.items()))
        w(f"  distance to unimpaired: untreated {inverse.distance_untreated_n:.2f} N, even split "
          f"{inverse.distance_even_split_n:.2f} N, best {inverse.distance_n:.2f} N "
          f"({inverse.evaluations} evaluations)")
        w(f"  {inverse.notice}")
    w("")
    out.extend(_severity_lines(c))
    w("")
    n = c.before.conditions.grid_m.shape[0]
    w(f"Field change on {n} grid points (moving: {c.before.conditions.velocities[-1].shape[0]} "
      "directions)")
    w(f"  {'speed':>6} {'RMS |F| N':>19} {'RMS |ΔF|':>9} {'max |ΔF|':>9} {'at (x, y) m':>17}"
      f" {'area ×':>7} {'Δθ':>6} {'shape ratio':>15}")
    w(f"  {'m/s':>6} {'before → after':>19} {'N':>9} {'N':>9} {'':>17} {'median':>7}"
      f" {'mean':>6} {'before → after':>15}")
    for f in c.fields:
        at = (f"({f.diff_max_at_m[0]:+.3f}, {f.diff_max_at_m[1]:+.3f})" if f.diff_max_n > 0
              else "-")
        w(f"  {f.speed_m_per_s:6.2f} {f.force_rms_before_n:8.2f} → {f.force_rms_after_n:<8.2f}"
          f" {f.diff_rms_n:9.2f} {f.diff_max_n:9.2f} {at:>17} {f.area_ratio_median:7.3f}"
          f" {f.orientation_change_deg_mean:5.1f}° {f.shape_ratio_before_median:6.1f} → "
          f"{f.shape_ratio_after_median:<6.1f}")
    p = c.potential
    where = (f" at ({p.max_at_m[0]:+.3f}, {p.max_at_m[1]:+.3f}) m" if p.max_abs_j > 0 else "")
    w(f"  potential energy ΔU: mean {p.mean_j:+.3f} J, RMS {p.rms_j:.3f} J, "
      f"largest {p.max_abs_j:.3f} J{where}")
    w("")
    w(f"  {'Probing motion':<14}{'peak force N':>26}{'direction at peak':>21}"
      f"{'mean direction':>19}")
    for name, b, a in c.probe_rows():
        w(f"  {name:<14}{b.peak_force_n:9.2f} → {a.peak_force_n:<8.2f}"
          f"{_pct(b.peak_force_n, a.peak_force_n):>8}   {_deg(b.peak_direction_rad)} → "
          f"{_deg(a.peak_direction_rad)}   {_deg(b.mean_direction_rad)} → "
          f"{_deg(a.mean_direction_rad)}")
    w("")
    out.extend(_stretch_lines(c))
    if course is not None:
        w("")
        w("Week by week after the injection (effect: drop of α; fast-stretch peak torque N·m)")
        names = list(course.stretch_peak_n_m)[:2]
        groups = list(course.effect)
        head = "".join(f"{'effect ' + g:>11}" for g in groups)
        head += "".join(f"{n:>18}" for n in names) + f"{'pull peak N':>13}"
        w(f"  {'week':>5}{head}")
        pull = course.probe_peak_n.get("pull")
        for i, wk in enumerate(course.weeks):
            row = "".join(f"{course.effect[g][i]:11.3f}" for g in groups)
            row += "".join(f"{course.stretch_peak_n_m[n][i]:18.2f}" for n in names)
            row += f"{pull[i]:13.2f}" if pull is not None else ""
            w(f"  {wk:5g}{row}")
    return "\n".join(out)
