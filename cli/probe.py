"""``fieldbank probe design|classify|paths|trials``: probing motions that tell candidate arms
apart, and which candidate made a recorded trace."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar

import click

from fieldbank import probechoices as pc
from fieldbank.cli.options import (
    MODEL_ID,
    db_option,
    emit,
    figure_path,
    json_option,
    option_group,
    output_file,
    say,
    xy_metres,
)
from fieldbank.cli.progress import counted
from fieldbank.errors import ParameterError
from fieldbank.files import to_json, write_atomic
from fieldbank.params import JOINT_GROUPS
from fieldbank.probepath import probes_document

if TYPE_CHECKING:  # typing only: the library loads when a command runs
    from fieldbank.evaluate.classify import Classification
    from fieldbank.evaluate.design import (
        Candidate,
        DesignReport,
        ProbeLimits,
        ProbeSetScore,
    )
    from fieldbank.evaluate.openset import OpenClassification
    from fieldbank.figures import Scene

F = TypeVar("F", bound=Callable[..., Any])




def candidate_options(f: F) -> F:
    """The candidate arms: synthetic severities, parameter files, stored models."""
    opts = [
        click.option("--groups", default="shoulder,elbow,biarticular", show_default=True,
                     help="Impaired groups of the synthetic candidates (or 'all')."),
        click.option("--levels", default=None,
                     help="Severities of the synthetic candidates, e.g. severe or "
                          "'very-mild,mild,moderate,severe' or 'all' (default: severe, or none "
                          "when other candidates are given)."),
        click.option("--unimpaired", is_flag=True, help="Add the unimpaired arm."),
        click.option("--candidate-params", "param_files", multiple=True,
                     type=click.Path(exists=True, dir_okay=False, path_type=Path),
                     help="A candidate from a parameter file (named by the file). Repeatable."),
        click.option("--candidate-model", "model_ids", multiple=True, type=MODEL_ID,
                     help="A candidate from a stored model id. Repeatable."),
        click.option("--mass", type=float, help="Body mass of the synthetic arms, kg."),
        click.option("--height", type=float, help="Height of the synthetic arms, m."),
        click.option("--side", type=click.Choice(["right", "left"]),
                     help="Side of the synthetic arms (default right)."),
    ]
    return option_group(*opts)(f)


def noise_options(f: F) -> F:
    """The noise model and what a hand feels."""
    opts = [
        click.option("--force-sd-n", type=float, default=pc.FORCE_SD_N, show_default=True,
                     help="Force noise per axis, N (assumption)."),
        click.option("--correlation-s", type=float, default=pc.CORRELATION_S,
                     show_default=True,
                     help="Time over which force noise decorrelates, s (assumption)."),
        click.option("--direction-sd-deg", type=float, default=pc.DIRECTION_SD_DEG,
                     show_default=True, help="Operator's scatter of a probe's direction, °."),
        click.option("--length-sd", type=float, default=pc.LENGTH_SD, show_default=True,
                     help="Operator's relative scatter of a probe's length."),
        click.option("--speed-sd", type=float, default=pc.SPEED_SD, show_default=True,
                     help="Operator's relative scatter of a probe's speed."),
        click.option("--force-jnd", type=float, default=pc.FORCE_JND, show_default=True,
                     help="Weber fraction of force magnitude."),
        click.option("--direction-jnd-deg", type=float, default=pc.DIRECTION_JND_DEG,
                     show_default=True, help="Force-direction threshold, °."),
        click.option("--free-exploration", is_flag=True,
                     help="Judge magnitudes with the free-exploration Weber fraction 0.6."),
    ]
    return option_group(*opts)(f)


def limit_options(f: F) -> F:
    """The probe limits (defaults: ProbeLimits())."""
    opts = [
        click.option("--max-speed", type=float, default=pc.MAX_SPEED_M_PER_S,
                     show_default=True,
                     help="Peak hand speed of a probe, m/s."),
        click.option("--force-limit-n", type=float, default=pc.FORCE_LIMIT_N,
                     show_default=True,
                     help="The renderer's force saturation, N."),
        click.option("--workspace", metavar="XMIN,XMAX,YMIN,YMAX",
                     help="Box the handle must stay in, robot frame, m."),
        click.option("--shoulder-offset", metavar="X,Y",
                     help="Shoulder position in robot coordinates, m (default 0,0)."),
    ]
    return option_group(*opts)(f)


def build_candidates(groups: str, levels: str | None, unimpaired: bool,
                     param_files: tuple[Path, ...], model_ids: tuple[int, ...],
                     mass: float | None, height: float | None, side: str | None,
                     db_url: str | None) -> list[Candidate]:
    from fieldbank.probeset import candidate_set

    return candidate_set(groups, levels, unimpaired, param_files, model_ids, mass, height,
                         side, db_url)


def build_limits(max_speed: float, force_limit_n: float, workspace: str | None,
                 shoulder_offset: str | None) -> tuple[ProbeLimits, tuple[float, float]]:
    """The probe limits and the shoulder's offset the options give (``--workspace`` read as
    XMIN,XMAX,YMIN,YMAX in metres)."""
    from fieldbank.probeset import probe_limits

    offset = xy_metres(shoulder_offset, "--shoulder-offset")
    box = None
    if workspace is not None:
        try:
            x0, x1, y0, y1 = (float(v) for v in workspace.split(","))
        except ValueError:
            raise click.BadParameter(f"--workspace must read XMIN,XMAX,YMIN,YMAX in metres; "
                                     f"got {workspace!r}") from None
        box = (x0, x1, y0, y1)
    return probe_limits(max_speed, force_limit_n, box, offset), offset


def _save_plot(fig: Scene, path: Path) -> None:
    from fieldbank.figures import save

    save(fig, path)
    say(f"plot: {path}")


# --- text read-outs ---------------------------------------------------------------------------
def _set_text(score: ProbeSetScore, side: str) -> list[str]:
    from fieldbank.evaluate.design import direction_words

    lines = []
    for p in score.probes:
        lines.append(f"  {p.name}: {p.motion.description} (peak speed "
                     f"{p.motion.peak_speed_m_per_s:.2f} m/s)")
        for f in p.features:
            words = direction_words(f.max_direction_deg, side)
            lines.append(f"    {f.candidate:<22} peak {f.max_force_n:6.1f} N toward "
                         f"{f.max_direction_deg:5.0f}° ({words}) at {f.max_at_s:.2f} s, "
                         f"{f.max_at_fraction * 100:.0f}% along")
    s = score.summary()
    lines.append(f"  information: {s['information_bits']:.2f} of {s['information_max_bits']:.2f}"
                 f" bits about the {score.target}; closest pair felt {s['worst_felt_jnd']:.1f} "
                 f"JND apart; worst pairwise error {s['worst_error_probability']:.2g}")
    miss = score.unseparated("feel")
    lines.append("  every pair felt apart" if not miss else
                 "  not felt apart: " + "; ".join(f"{a} / {b}" for a, b in miss))
    return lines


def _notes(cands: list[Candidate]) -> list[str]:
    return [f"note: {c.name}: {n}" for c in cands for n in c.notes]


def _design_text(rep: DesignReport, side: str) -> str:
    d = rep.design
    lines = [f"designed ({d.criterion}, {d.family}s, target {d.score.target}; search "
             f"{d.search_s:.2f} s, {d.evaluations} paths evaluated):"]
    lines += _set_text(d.score, side)
    lines.append("the seed's pull and semi-ellipse, measured the same way:")
    lines += _set_text(rep.seed, side)
    return "\n".join(lines)


@click.group("probe")
def probe() -> None:
    """Design probing motions that tell candidate arms apart; classify recorded traces."""


@probe.command("design")
@candidate_options
@click.option("--criterion", type=click.Choice(pc.CRITERIA), default=pc.DEFAULT_CRITERION,
              show_default=True,
              help="feel: felt differences in JNDs; information: bits; orientation / minmax: "
                   "the seed's paradigms alone.")
@click.option("--family", type=click.Choice(pc.PATH_FAMILIES), default=None,
              help="stroke (default) or circle (default for --criterion minmax).")
@click.option("--target", type=click.Choice(pc.TARGETS), default=pc.DEFAULT_TARGET,
              show_default=True,
              help="Tell every candidate apart, or only the impaired groups.")
@click.option("--max-probes", type=click.IntRange(min=1), default=None,
              help="At most this many probes (default: number of candidates - 1).")
@noise_options
@limit_options
@click.option("--out", type=click.Path(dir_okay=False, path_type=Path), callback=output_file,
              help="Write the probes (polylines in the robot frame with timing) as JSON.")
@click.option("--plot", "plot_path", type=click.Path(dir_okay=False, path_type=Path),
              callback=figure_path,
              help="Figure of the paths and force profiles (.svg, .png or .pdf).")
@db_option
@json_option
def design_cmd(groups: str, levels: str | None, unimpaired: bool, param_files: tuple[Path, ...],
               model_ids: tuple[int, ...], mass: float | None, height: float | None,
               side: str | None, criterion: str, family: str | None, target: str,
               max_probes: int | None, force_sd_n: float, correlation_s: float,
               direction_sd_deg: float, length_sd: float, speed_sd: float, force_jnd: float,
               direction_jnd_deg: float, free_exploration: bool, max_speed: float,
               force_limit_n: float, workspace: str | None, shoulder_offset: str | None,
               out: Path | None, plot_path: Path | None, db_url: str | None,
               as_json: bool) -> None:
    """Find the probing motions that best tell the candidate arms apart."""
    from fieldbank.evaluate.design import design_report
    from fieldbank.figures.probes import probe_figure
    from fieldbank.probeset import noise_and_perception

    cands = build_candidates(groups, levels, unimpaired, param_files, model_ids, mass, height,
                             side, db_url)
    noise, perception = noise_and_perception(force_sd_n, correlation_s, direction_sd_deg,
                                             length_sd, speed_sd, force_jnd, direction_jnd_deg,
                                             free_exploration)
    limits, offset = build_limits(max_speed, force_limit_n, workspace, shoulder_offset)
    fam = family or ("circle" if criterion == "minmax" else "stroke")
    rep = design_report(cands, criterion=criterion, family=fam, target=target,
                        max_probes=max_probes, perception=perception, noise=noise,
                        limits=limits)
    doc = rep.to_dict(offset)
    if out is not None:
        write_atomic(out, to_json(probes_document([m.path(offset)
                                                   for m in rep.design.motions])) + "\n")
        say(f"probes: {out}")
    if plot_path is not None:
        _save_plot(probe_figure(rep.design.score, cands, "designed probes"), plot_path)
    arm_side = "left" if cands[0].arm.mirror else "right"
    emit(doc, as_json, "\n".join([_design_text(rep, arm_side), *_notes(cands)]))


def _classification_text(cl: Classification) -> str:
    from fieldbank.evaluate.classify import FIT_LEVEL

    lines = [cl.verdict()]
    if cl.knows_groups:
        lines.append("  groups: " + ", ".join(f"{g} {p:.3g}"
                                              for g, p in cl.group_posterior.items()))
        lines.append("  levels: " + ", ".join(f"{g} {p:.3g}"
                                              for g, p in cl.level_posterior.items()))
    order = sorted(range(len(cl.candidates)), key=lambda k: -cl.posterior[k])
    for k in order[:6]:
        lines.append(f"    {cl.candidates[k].name:<22} p = {cl.posterior[k]:.3g}   residual "
                     f"{cl.rms_residual_n[k]:.2f} N RMS")
    lines.append(f"  likelihood ratio best : runner-up = 10^{cl.log10_likelihood_ratio:.1f}")
    lines.append(f"  fit of the closest candidate: p = {cl.fit_p_value:.3g} under the noise model"
                 f" (below {FIT_LEVEL:g}: none of the candidates explains the trace); "
                 f"probabilities tempered ×1/{cl.temperature:.3g} for "
                 f"{cl.model_error_n:.2g} N of model error")
    if cl.next_probe is not None:
        p = cl.next_probe.score.probes[0]
        lines.append(f"next probe: {p.motion.description}; {cl.next_reason}")
    else:
        lines.append(f"next probe: {cl.next_reason}")
    return "\n".join(lines)


@probe.command("classify")
@click.argument("traces", nargs=-1, required=True, metavar="TRACE...")
@candidate_options
@noise_options
@limit_options
@click.option("--predictor", type=click.Choice(pc.PREDICTORS), default=pc.DEFAULT_PREDICTOR,
              show_default=True,
              help="replay: the recorded motion drives each candidate's virtual arm (rendered "
                   "traces); rigid: muscles and inertia of a rigidly held arm (measured "
                   "traces); static: the muscles' force at the recorded position and velocity.")
@click.option("--model", type=click.Choice(["A", "B"]), default=None,
              help="In a session that rendered two models, the ticks of this one.")
@click.option("--no-next", is_flag=True, help="Do not design the next probe.")
@click.option("--open", "open_set", is_flag=True,
              help="Among every state of every muscle group of the body (--mass, --height, "
                   "--side): each group unimpaired, or its stiffness, spasticity or both at a "
                   "half step of the severity scale, its reflex raised by α or β alone, or a "
                   "contracture of 5-20 mm; up to two "
                   "groups at once. Says per group whether it is impaired and how, and when "
                   "none of these explains the recording. Best with the stretch of every group "
                   "(fieldbank.evaluate.design.coverage.stretch_set).")
@click.option("--plot", "plot_path", type=click.Path(dir_okay=False, path_type=Path),
              callback=figure_path,
              help="Figure of the recorded and predicted forces and the posterior (.svg, .png "
                   "or .pdf).")
@db_option
@json_option
def classify_cmd(traces: tuple[str, ...], groups: str, levels: str | None, unimpaired: bool,
                 param_files: tuple[Path, ...], model_ids: tuple[int, ...],
                 mass: float | None, height: float | None, side: str | None,
                 force_sd_n: float, correlation_s: float, direction_sd_deg: float,
                 length_sd: float, speed_sd: float, force_jnd: float,
                 direction_jnd_deg: float, free_exploration: bool, max_speed: float,
                 force_limit_n: float, workspace: str | None, shoulder_offset: str | None,
                 predictor: str, model: str | None, no_next: bool, open_set: bool,
                 plot_path: Path | None, db_url: str | None, as_json: bool) -> None:
    """Name the candidate arm most likely to have made the recorded TRACEs, and the next probe.

    A TRACE is a haptic trace file (.h5), a database session (haptic_session:ID) or a CSV with
    columns t_s,x_m,y_m,fx_n,fy_n (and vx_m_per_s,vy_m_per_s) and '# frame:' / '# sign:' lines.
    """
    from fieldbank.evaluate.classify import classify
    from fieldbank.figures.probes import classification_figure
    from fieldbank.haptic.probe import read_observations
    from fieldbank.probeset import noise_and_perception

    if open_set:
        _open_classify(traces, levels, param_files, model_ids, mass, height, side, force_sd_n,
                       correlation_s, shoulder_offset, model, plot_path, db_url, as_json)
        return
    cands = build_candidates(groups, levels if levels is not None else
                             (None if param_files or model_ids else "all"), unimpaired,
                             param_files, model_ids, mass, height, side, db_url)
    noise, perception = noise_and_perception(force_sd_n, correlation_s, direction_sd_deg,
                                             length_sd, speed_sd, force_jnd, direction_jnd_deg,
                                             free_exploration)
    limits, offset = build_limits(max_speed, force_limit_n, workspace, shoulder_offset)
    obs = read_observations(traces, db_url, model,
                            offset if shoulder_offset is not None else None)
    cl = classify(obs, cands, noise=noise, predictor=predictor, next_probe=not no_next,
                  perception=perception, limits=limits)
    if plot_path is not None:
        _save_plot(classification_figure(cl), plot_path)
    emit(cl.to_dict(offset), as_json, "\n".join([_classification_text(cl), *_notes(cands)]))


def _open_classify(traces: tuple[str, ...], levels: str | None, param_files: tuple[Path, ...],
                   model_ids: tuple[int, ...], mass: float | None, height: float | None,
                   side: str | None, force_sd_n: float, correlation_s: float,
                   shoulder_offset: str | None, model: str | None, plot_path: Path | None,
                   db_url: str | None, as_json: bool) -> None:
    from fieldbank import modelsource
    from fieldbank.evaluate.design import NoiseModel
    from fieldbank.evaluate.openset import classify_on_body
    from fieldbank.evaluate.statements import open_report
    from fieldbank.haptic.probe import read_observations

    given = [name for name, v in (("--levels", levels), ("--candidate-params", param_files),
                                  ("--candidate-model", model_ids), ("--plot", plot_path))
             if v]
    if given:
        raise click.UsageError(f"--open classifies among every state of every group of the "
                               f"body; {', '.join(given)} do not apply to it.")
    offset = xy_metres(shoulder_offset, "--shoulder-offset")
    obs = read_observations(traces, db_url, model,
                            offset if shoulder_offset is not None else None)
    body = modelsource.synthetic([], body_mass_kg=mass, height_m=height, side=side).params
    cl = classify_on_body(obs, body, NoiseModel(force_sd_n=force_sd_n,
                                                correlation_s=correlation_s))
    emit(open_report(cl), as_json, _open_text(cl))


def _open_text(cl: OpenClassification) -> str:
    from fieldbank.evaluate.classify import FIT_LEVEL
    from fieldbank.evaluate.openset import NONE_OF_THEM
    from fieldbank.evaluate.openstates import KINDS
    from fieldbank.evaluate.statements import state
    from fieldbank.params import GROUP_NAMES

    answer, p = cl.answer
    said = ("none of the candidates explains the recording" if answer == NONE_OF_THEM else
            "no group impaired" if answer == "unimpaired" else f"impaired: {answer}")
    lines = ["stated (per group, or partner groups the recording cannot tell apart):"]
    lines += [f"  p = {s.probability:.2f}  {s.text}" for s in state(cl)]
    lines += [f"most probable set of groups: {said}  (p = {p:.2f})",
              f"  {'group':<28} {'impaired':>8}   " + "  ".join(f"{k:>10}" for k in
                                                             ("spasticity", "stiffness",
                                                              "both", "contracture"))]
    for g, kinds in cl.group_kinds().items():
        row = [kinds[KINDS[1]], kinds[KINDS[0]], kinds[KINDS[2]], kinds[KINDS[3]]]
        lines.append(f"  {GROUP_NAMES[g] + ' (' + g + ')':<28} {cl.group_probability[g]:>8.2f}"
                     "   " + "  ".join(f"{v:>10.2f}" for v in row))
    level = cl.calibration.misfit_level
    lines.append(f"  none of the candidates: p = {cl.other_probability:.2f} (fit of the most "
                 f"probable arm: p = {cl.fit_p_value:.3g} under the noise model; below "
                 f"{FIT_LEVEL:g} none of them explains it"
                 + (f", below {level:g} this rises)" if level > FIT_LEVEL else
                    f", and below it this rises; at least {cl.calibration.other:.2f}: an arm "
                    "outside the candidates that fits within the noise)"))
    lines.append(f"  most probable arm: {', '.join(cl.best)}")
    lines.append("  spasticity: velocity-dependent resistance (the stretch reflex); stiffness: "
                 "position-dependent, slack length normal; contracture: the slack length short")
    return "\n".join(lines)


@probe.command("paths")
@candidate_options
@click.option("--radii-cm", default="4,6,8", show_default=True,
              help="Radii of the circles around the equilibrium, cm.")
@noise_options
@limit_options
@click.option("--plot", "plot_path", type=click.Path(dir_okay=False, path_type=Path),
              callback=figure_path,
              help="Figure of the paths and force profiles (.svg, .png or .pdf).")
@db_option
@json_option
def paths_cmd(groups: str, levels: str | None, unimpaired: bool, param_files: tuple[Path, ...],
              model_ids: tuple[int, ...], mass: float | None, height: float | None,
              side: str | None, radii_cm: str, force_sd_n: float, correlation_s: float,
              direction_sd_deg: float, length_sd: float, speed_sd: float, force_jnd: float,
              direction_jnd_deg: float, free_exploration: bool, max_speed: float,
              force_limit_n: float, workspace: str | None, shoulder_offset: str | None,
              plot_path: Path | None, db_url: str | None, as_json: bool) -> None:
    """The min-max and orientation paradigms on the seed's pull, semi-ellipse and circles."""
    from fieldbank.evaluate.design import circles, equilibrium, paradigms, seed_probes
    from fieldbank.figures.probes import probe_figure
    from fieldbank.probeset import noise_and_perception

    cands = build_candidates(groups, levels, unimpaired, param_files, model_ids, mass, height,
                             side, db_url)
    noise, perception = noise_and_perception(force_sd_n, correlation_s, direction_sd_deg,
                                             length_sd, speed_sd, force_jnd, direction_jnd_deg,
                                             free_exploration)
    limits, _offset = build_limits(max_speed, force_limit_n, workspace, shoulder_offset)
    try:
        radii = [float(r) / 100.0 for r in radii_cm.split(",") if r.strip()]
    except ValueError:
        raise click.BadParameter(f"--radii-cm must be numbers; got {radii_cm!r}") from None
    arm_side = "left" if cands[0].arm.mirror else "right"
    motions = seed_probes(cands) + circles(equilibrium(cands), radii, side=arm_side)
    closed = [False, False] + [True] * len(radii)
    res = paradigms(cands, motions, closed=closed, perception=perception, noise=noise,
                    limits=limits)
    if plot_path is not None:
        _save_plot(probe_figure(res.score, cands, "the seed's probes and circles"), plot_path)
    lines = []
    for p in res.score.probes:
        lines.append(f"{p.name}: {p.motion.description}")
        for f in p.features:
            lines.append(f"  {f.candidate:<22} max {f.max_force_n:6.1f} N at "
                         f"{f.max_at_fraction * 100:3.0f}% toward {f.max_direction_deg:5.0f}°, "
                         f"min {f.min_force_n:5.1f} N at {f.min_at_fraction * 100:3.0f}%")
    for what, chosen, ok in (("min-max", res.minmax_set, res.minmax_complete),
                             ("orientation", res.orientation_set, res.orientation_complete)):
        lines.append(f"{what} paradigm: {', '.join(chosen) or 'no path'} "
                     + ("separates every pair" if ok else "does not separate every pair"))
    emit(res.to_dict(), as_json, "\n".join(lines + _notes(cands)))


@probe.command("trials")
@click.option("--groups", default="shoulder,elbow,biarticular", show_default=True,
              help="Impaired groups of the true arms (and the candidates).")
@click.option("--levels", default="all", show_default=True,
              help="Severities of the true arms (and the candidates).")
@click.option("--reps", type=click.IntRange(min=1), default=3, show_default=True,
              help="Executions of each probe set on each (group, severity) arm.")
@click.option("--draws", type=click.IntRange(min=1), default=4, show_default=True,
              help="Force-noise draws met by each execution.")
@click.option("--max-probes", type=click.IntRange(min=1), default=2, show_default=True,
              help="Probes in the designed set (the seed's set has 2).")
@click.option("--criterion", type=click.Choice(pc.CRITERIA), default="information",
              show_default=True)
@noise_options
@click.option("--seed", "rng_seed", type=int, default=0, show_default=True)
@json_option
def trials_cmd(groups: str, levels: str, reps: int, draws: int, max_probes: int,
               criterion: str, force_sd_n: float, correlation_s: float,
               direction_sd_deg: float, length_sd: float, speed_sd: float, force_jnd: float,
               direction_jnd_deg: float, free_exploration: bool, rng_seed: int,
               as_json: bool) -> None:
    """Simulated identification trials: designed probes against the seed's, confusion matrices."""
    from fieldbank.evaluate.design import severity_candidates
    from fieldbank.evaluate.severity import LEVELS, group_name, level_name
    from fieldbank.haptic.identify import designed_vs_seed
    from fieldbank.probeset import ALL_LEVELS, named_list, noise_and_perception

    gs = named_list(groups, group_name, tuple(JOINT_GROUPS))
    ls = named_list(levels, level_name, ALL_LEVELS)
    if not gs or not ls or LEVELS[0] in ls:
        raise ParameterError("Give impaired groups and levels from very mild to severe.")
    noise, perception = noise_and_perception(force_sd_n, correlation_s, direction_sd_deg,
                                             length_sd, speed_sd, force_jnd, direction_jnd_deg,
                                             free_exploration)
    say("designing the probes, then the trials (a bar counts them on a terminal)")
    with counted("trials", "trial") as bar:
        rep, res = designed_vs_seed(
            severity_candidates(gs, ls), groups=gs, levels=ls, repetitions=reps,
            noise_draws=draws, noise=noise, perception=perception, criterion=criterion,
            max_probes=max_probes, seed=rng_seed, progress=bar)
    doc = {"designed": rep.design.to_dict(), "seed_probes": rep.seed.to_dict(),
           "trials": res.to_dict()}
    head = ("designed: " + "; ".join(p.describe() for p in rep.design.paths)
            + f"\n{reps} execution(s) × {draws} noise draw(s) per arm; force noise "
              f"{noise.force_sd_n:g} N per axis, τ {noise.correlation_s:g} s")
    emit(doc, as_json, head + "\n" + res.table())
