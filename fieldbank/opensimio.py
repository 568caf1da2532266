"""OpenSim files: a trace as ``.mot``/``.sto``, a fitted arm as an ``.osim`` model.

**Storage files** (``.mot`` and ``.sto``, OpenSim's tab-separated tables): a header of
``key=value`` lines — the table's name on the first line, ``version=1``, ``nRows``,
``nColumns`` (time included), ``inDegrees=no`` — closed by ``endheader``, then a row of column
labels starting with ``time`` and one row per sample. Units are not part of the format, so each
label carries its unit (``x_m``, ``fx_n``, …: fieldbank's column names already do) and the
header lists them as ``units_<label>=…`` lines, which OpenSim keeps as metadata.

**The arm** (``.osim``, OpenSim 4 XML): the two segments of BRIEF §3 as bodies ``upper_arm`` and
``forearm`` (forearm and hand; lengths, masses, centres of mass and inertias of the patient's
parameters, Winter 2004), joined to the ground at the shoulder and to each other at the elbow by
pin joints about the vertical z axis (the arm moves in the horizontal x–y plane; gravity along
−z does no work there); coordinates ``shoulder_flexion`` and ``elbow_flexion`` in rad, with the
range of motion and the rest posture as defaults. The six muscle groups are path actuators
(``PathActuator``: sf, se, ef, ee, bf, be) whose path length is the model's muscle length
λ_rest + J_λ (q − q_rest) exactly — built of path points that move with the joint coordinates
(``MovingPathPoint``), so OpenSim's moment arms are the model's constant ones (ρ for a flexor,
−ρ for an extensor); ``optimal_force`` is the fitted reflex strength α (N). The passive stiffness is a ``PathSpring`` on the same path
per group (``<group>_passive``: stiffness Km, N/m; resting length λ_rest, m). The stretch gain
β and the rest lengths have no OpenSim property; they are written, with every other parameter,
as the model's ``fieldbank.arm-params`` document in its ``publications`` text (read it back
with :meth:`fieldbank.params.ArmParams.from_dict`). OpenSim's own muscle models do not follow
the seed's reflex (eqs. 3–4): simulating the reflex needs fieldbank, not the ``.osim``.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from xml.sax.saxutils import escape

import numpy as np

from fieldbank.errors import FieldbankError
from fieldbank.model import Arm
from fieldbank.params import GROUPS, ArmParams


class OpenSimError(FieldbankError, ValueError):
    """A table or model that cannot be written as an OpenSim file."""


def storage_text(name: str, t_s: Sequence[float] | np.ndarray,
                 columns: Mapping[str, np.ndarray], units: Mapping[str, str]) -> str:
    """A ``.mot``/``.sto`` table: ``time`` then each column (label → (N,) values)."""
    t = np.asarray(t_s, dtype=float)
    if t.ndim != 1 or t.size == 0:
        raise OpenSimError(f"{name}: time must be a non-empty vector; got shape {t.shape}")
    labels = list(columns)
    for label in labels:
        if np.asarray(columns[label]).shape != t.shape:
            raise OpenSimError(f"{name}: column {label!r} has shape "
                               f"{np.asarray(columns[label]).shape}, time has {t.shape}")
        if any(c in label for c in "\t\r\n"):
            raise OpenSimError(f"{name}: column label {label!r} holds a tab or a line break")
    safe = name.replace("\n", " ").replace("\r", " ")
    lines = [safe, "version=1", f"nRows={t.size}", f"nColumns={len(labels) + 1}",
             "inDegrees=no", "units_time=s"]
    lines += [f"units_{label}={units.get(label, '')}" for label in labels]
    lines.append("endheader")
    lines.append("\t".join(["time", *labels]))
    data = np.column_stack([t, *[np.asarray(columns[c], dtype=float) for c in labels]])
    lines += ["\t".join(f"{v:.10g}" for v in row) for row in data]
    return "\n".join(lines) + "\n"


def read_storage(text: str) -> tuple[dict[str, str], list[str], np.ndarray]:
    """(header keys, column labels, data) of a ``.mot``/``.sto`` text (for round trips)."""
    head, sep, body = text.partition("endheader\n")
    if not sep:
        raise OpenSimError("no 'endheader' line: not an OpenSim storage file")
    keys: dict[str, str] = {}
    for ln in head.splitlines()[1:]:
        k, eq, v = ln.partition("=")
        if eq:
            keys[k.strip()] = v.strip()
    rows = body.strip("\n").split("\n")
    labels = rows[0].split("\t")
    data = np.array([[float(x) for x in r.split("\t")] for r in rows[1:]], dtype=float)
    return keys, labels, data.reshape(-1, len(labels))


# --- the arm as an OpenSim model ---------------------------------------------------------------
def _v(*xs: float) -> str:
    return " ".join(f"{x:.17g}" for x in xs)


def _const(v: float) -> str:
    return f"<Constant><value>{v:.17g}</value></Constant>"


def _moving(name: str, coord: str, slope: float, intercept: float) -> str:
    """A path point on the ground at x = slope·q + intercept (q the coordinate)."""
    return (f'<MovingPathPoint name="{name}"><socket_parent_frame>/ground'
            f"</socket_parent_frame><socket_x_coordinate>{coord}</socket_x_coordinate>"
            f"<socket_y_coordinate>{coord}</socket_y_coordinate>"
            f"<socket_z_coordinate>{coord}</socket_z_coordinate>"
            f"<x_location><LinearFunction><coefficients>{_v(slope, intercept)}</coefficients>"
            f"</LinearFunction></x_location><y_location>{_const(0.0)}</y_location>"
            f"<z_location>{_const(0.0)}</z_location></MovingPathPoint>")


def _offset(name: str, parent: str, xyz: tuple[float, float, float]) -> str:
    return (f'<PhysicalOffsetFrame name="{name}"><socket_parent>{parent}</socket_parent>'
            f"<translation>{_v(*xyz)}</translation><orientation>0 0 0</orientation>"
            "</PhysicalOffsetFrame>")


def _path(points: str) -> str:
    return (f'<GeometryPath name="path"><PathPointSet><objects>{points}</objects>'
            "</PathPointSet></GeometryPath>")


SHOULDER = "/jointset/shoulder/shoulder_flexion"
ELBOW = "/jointset/elbow/elbow_flexion"


def arm_osim(params: ArmParams, name: str = "fieldbank_arm") -> str:
    """The arm of ``params`` as an OpenSim 4 model (see the module docstring)."""
    arm = Arm.from_params(params)
    p = params
    l1, l2 = float(arm.l1), float(arm.l2)
    m1, m2 = p.upper_arm_mass_kg, p.forearm_mass_kg
    c1, c2 = p.upper_arm_com_m, p.forearm_com_m
    i1, i2 = p.upper_arm_inertia_kg_m2, p.forearm_inertia_kg_m2
    (s_lo, s_hi), (e_lo, e_hi) = p.shoulder_range_rad, p.elbow_range_rad
    q1r, q2r = (float(v) for v in arm.q_rest)
    jl = np.asarray(arm.jl, dtype=float)            # (6, 2): λ̇ = J_λ q̇
    # Each path runs P1 → P0 → P2 along the ground's x axis: P1 at x = −(A + a·q1) left of the
    # origin, P0 at the origin, P2 at x = B + b·q2 right of it, so its length is
    # A + B + a·q1 + b·q2 = λ_rest + J_λ (q − q_rest) exactly: the model's muscle length, with
    # its constant moment arms (OpenSim's moment arm −∂L/∂q is ρ for a flexor).
    forces = []
    for i, g in enumerate(GROUPS):
        a, b = (float(v) for v in jl[i])
        lam = float(arm.lam_rest[i])
        big_a = 0.5 * lam - a * q1r
        big_b = 0.5 * lam - b * q2r
        pts = (_moving(f"{g}_shoulder", SHOULDER, -a, -big_a)
               + f'<PathPoint name="{g}_origin"><socket_parent_frame>/ground'
                 "</socket_parent_frame><location>0 0 0</location></PathPoint>"
               + _moving(f"{g}_elbow", ELBOW, b, big_b))
        forces.append(f'<PathActuator name="{g}"><appliesForce>true</appliesForce>'
                      f"<optimal_force>{p.alpha_n[i]:.17g}</optimal_force>"
                      f"<min_control>0</min_control><max_control>1</max_control>"
                      f"{_path(pts)}</PathActuator>")
        forces.append(f'<PathSpring name="{g}_passive"><appliesForce>true</appliesForce>'
                      f"<resting_length>{lam:.17g}</resting_length>"
                      f"<stiffness>{p.km_n_per_m[i]:.17g}</stiffness>"
                      f"<dissipation>0</dissipation>{_path(pts.replace(g + '_', g + '_p_'))}"
                      "</PathSpring>")
    doc = escape(params.to_json())

    def body(bname: str, mass: float, com: float, inertia: float) -> str:
        return (f'<Body name="{bname}"><mass>{mass:.17g}</mass>'
                f"<mass_center>{_v(com, 0, 0)}</mass_center>"
                f"<inertia>{_v(1e-4, inertia, inertia, 0, 0, 0)}</inertia></Body>")

    def pin(jname: str, parent: str, at: float, child: str, coord: str, lo: float, hi: float,
            default: float) -> str:
        parent_path = "/ground" if parent == "ground" else "/bodyset/" + parent
        return (f'<PinJoint name="{jname}"><socket_parent_frame>{parent}_offset'
                f"</socket_parent_frame><socket_child_frame>{child}_offset"
                f"</socket_child_frame><coordinates><Coordinate name=\"{coord}\">"
                f"<default_value>{default:.17g}</default_value><range>{_v(lo, hi)}</range>"
                f"<clamped>false</clamped></Coordinate></coordinates><frames>"
                f"{_offset(parent + '_offset', parent_path, (at, 0.0, 0.0))}"
                f"{_offset(child + '_offset', '/bodyset/' + child, (0.0, 0.0, 0.0))}"
                "</frames></PinJoint>")

    side_word = "left (mirrored: +x to the patient's right)" if arm.mirror else "right"
    return (
        '<?xml version="1.0" encoding="UTF-8" ?>\n'
        '<OpenSimDocument Version="40000">'
        f'<Model name="{escape(name)}">'
        f"<credits>fieldbank: two-segment, six-muscle-group arm of Melendez-Calderon et al. "
        f"(seed eqs. 1-5), {side_word} arm; lengths m, masses kg, forces N</credits>"
        f"<publications>{doc}</publications>"
        "<length_units>meters</length_units><force_units>N</force_units>"
        f"<gravity>{_v(0, 0, -9.80665)}</gravity>"
        '<Ground name="ground"/>'
        "<BodySet><objects>"
        f"{body('upper_arm', m1, c1, i1)}"
        f"{body('forearm', m2, c2, i2)}"
        "</objects></BodySet>"
        "<JointSet><objects>"
        f"{pin('shoulder', 'ground', 0.0, 'upper_arm', 'shoulder_flexion', s_lo, s_hi, q1r)}"
        f"{pin('elbow', 'upper_arm', l1, 'forearm', 'elbow_flexion', e_lo, e_hi, q2r)}"
        "</objects></JointSet>"
        f"<ForceSet><objects>{''.join(forces)}</objects></ForceSet>"
        f"<MarkerSet><objects><Marker name=\"handle\"><socket_parent_frame>/bodyset/forearm"
        f"</socket_parent_frame><location>{_v(l2, 0, 0)}</location></Marker></objects>"
        "</MarkerSet>"
        "</Model></OpenSimDocument>\n")
