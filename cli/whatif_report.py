"""Plain-text before/after tables for ``fieldbank whatif``."""

from __future__ import annotations

import math

from fieldbank.evaluate.compare import Comparison
from fieldbank.interventions.course import TimeCourse
from fieldbank.interventions.inverse import DoseSplitResult
from fieldbank.interventions.plan import Plan


def _pct(before: float, after: float) -> str:
    if abs(before) < 1e-12:
        return "" if abs(after) < 1e-12 else "   (new)"
    return f"{100.0 * (after - before) / before:+7.1f}%"


def _deg(rad: float) -> str:
    return f"{math.degrees(rad):6.0f}°"


def render_text(source: str, plan: Plan, c: Comparison, course: TimeCourse | None = None,
                inverse: DoseSplitResult | None = None) -> str:
    out: list[str] = []
    w = out.append
    w(f"Model:  {source}")
    w("Plan:")
    out.extend(f"  {line}" for line in plan.describe())
    w("Model predictions, not treatment advice.")
    if inverse is not None:
        w("")
        w("Inverse what-if (botulinum split under a total of "
          f"{inverse.total_units_limit:g} U, week {inverse.weeks_since:g}):")
        w("  " + ", ".join(f"{g} {u:g} U" for g, u in inverse.units.items()))
        w(f"  distance to unimpaired: untreated {inverse.distance_untreated_n:.2f} N, even split "
          f"{inverse.distance_even_split_n:.2f} N, best {inverse.distance_n:.2f} N "
          f"({inverse.evaluations} evaluations)")
        w(f"  {inverse.notice}")
    w("")
    w(f"  {'Severity (passive Km)':<28}{'before':>14}{'after':>14}")
    for g, sb, sa in c.severity_rows():
        w(f"  {g:<28}{sb.level:>14}{sa.level:>14}   score {sb.score:.2f} → {sa.score:.2f}")
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
    speed = c.before.stretches[0].speed_deg_s
    w(f"  {f'Fast stretch ({speed:.0f}°/s)':<24}{'peak resisting torque N·m':>27}"
      f"{'reflex part N·m':>20}")
    for name, jb, ja in c.stretch_rows():
        w(f"  {name:<24}{jb.peak_torque_n_m:9.2f} → {ja.peak_torque_n_m:<8.2f}"
          f"{_pct(jb.peak_torque_n_m, ja.peak_torque_n_m):>8}"
          f"{jb.reflex_torque_n_m:12.2f} → {ja.reflex_torque_n_m:<8.2f}")
    if course is not None:
        w("")
        w("Week by week after the injection")
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
