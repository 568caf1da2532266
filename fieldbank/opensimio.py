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
(``PathActuator``: sf, se, ef, ee, bf, be) whose path wraps a cylinder of the group's moment
arm ρ about each joint it crosses, from a point just outside the cylinder on the parent segment
to one on the child: while a path wraps, its length is a constant plus ρ times the wrap angle,
which turns with the joint one for one, so OpenSim's moment arms are the model's constant ones
(ρ for a flexor, −ρ for an extensor; exact to 1e-15 m over the whole range of motion,
tests/test_measure_io.py). ``optimal_force`` is the fitted reflex strength α (N). The passive
stiffness is a ``PathSpring`` on the same path per group (``<group>_passive``: stiffness Km,
N/m, resting length the path's length at the rest posture — the linear part of eq. 5 at rest
length; OpenSim has no element for its exp(−ε²) factor). The stretch gain β and every other
parameter are written as the model's ``fieldbank.arm-params`` document in its
``publications`` text (read back with :meth:`fieldbank.params.ArmParams.from_dict`); OpenSim's
muscles do not follow the seed's reflex (eqs. 3–4), so simulating the reflex needs fieldbank.
A left arm is written in the right-arm (model) frame: mirror x to get the patient's frame.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from xml.sax.saxutils import escape

import numpy as np

from fieldbank.errors import FieldbankError
from fieldbank.model import Arm
from fieldbank.params import GROUPS, ArmParams

#: The model's coordinates (shoulder, elbow), rad: the .osim's names, and the .mot columns of
#: a trace's joint angles.
COORDINATES = ("shoulder_flexion", "elbow_flexion")


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


def _offset(name: str, parent: str, xyz: tuple[float, float, float]) -> str:
    return (f'<PhysicalOffsetFrame name="{name}"><socket_parent>{parent}</socket_parent>'
            f"<translation>{_v(*xyz)}</translation><orientation>0 0 0</orientation>"
            "</PhysicalOffsetFrame>")


#: Path points sit this far out from a wrap cylinder, in radii: close, so the path stays on the
#: cylinder over a 150° range (it leaves it when the wrap angle drops under 2·acos(1/1.01) ≈
#: 16°), and outside it, as OpenSim requires.
POINT_RADII = 1.01
#: Wrap angle at the end of the range where the path wraps least, and at most (degrees).
LEAST_WRAP_DEG = 21.0


def _cylinder(name: str, centre: tuple[float, float], radius: float) -> str:
    return (f'<WrapCylinder name="{name}"><xyz_body_rotation>0 0 0</xyz_body_rotation>'
            f"<translation>{_v(centre[0], centre[1], 0.0)}</translation>"
            f"<active>true</active><quadrant>all</quadrant><radius>{radius:.17g}</radius>"
            f"<length>0.2</length></WrapCylinder>")


def _point(name: str, frame: str, xy: tuple[float, float]) -> str:
    return (f'<PathPoint name="{name}"><socket_parent_frame>{frame}</socket_parent_frame>'
            f"<location>{_v(xy[0], xy[1], 0.0)}</location></PathPoint>")


def _wrap_angles(flexor: bool, lo: float, hi: float) -> tuple[float, float]:
    """(angle of the point on the parent, angle of the point on the child at q = 0), rad,
    around the joint: the wrap angle is K − q for a flexor (it shortens under flexion) and
    q − K' for an extensor, LEAST_WRAP_DEG at the end of the range [lo, hi] where it is least."""
    least = math.radians(LEAST_WRAP_DEG)
    if flexor:
        phi_o = math.pi / 2
        phi_i = phi_o - (hi + least)              # separation phi_o − (phi_i + q) = hi + least − q
    else:
        phi_o = -math.pi / 2
        phi_i = phi_o + least - lo                # separation (phi_i + q) − phi_o = q − lo + least
    return phi_o, phi_i


def _path(points: list[str], wraps: list[tuple[str, int, int]]) -> str:
    wr = "".join(f'<PathWrap name="w{k}"><wrap_object>{w}</wrap_object><method>hybrid</method>'
                 f"<range>{r0} {r1}</range></PathWrap>" for k, (w, r0, r1) in enumerate(wraps))
    return (f'<GeometryPath name="path"><PathPointSet><objects>{"".join(points)}</objects>'
            f"</PathPointSet><PathWrapSet><objects>{wr}</objects></PathWrapSet></GeometryPath>")


def _wrapped_length(rho: float, separation: float) -> float:
    """Length of a path from a point POINT_RADII·ρ from a cylinder's axis around it to another
    such point ``separation`` rad away: two tangent segments and the arc between them."""
    d = POINT_RADII * rho
    off = math.acos(rho / d)
    return 2.0 * math.sqrt(d * d - rho * rho) + rho * (separation - 2.0 * off)


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
    # Each group's path wraps a cylinder of its moment arm ρ about every joint it crosses, from
    # a point just outside the cylinder on the parent to one on the child: while it wraps, its
    # length is a constant plus ρ times the wrap angle, which follows the joint angle one for
    # one — a constant moment arm, flexors on the side that shortens under flexion.
    forces = []
    wraps_ground: list[str] = []
    wraps_upper: list[str] = []
    ranges = (p.shoulder_range_rad, p.elbow_range_rad)
    centres = (("/ground", (0.0, 0.0)), ("/bodyset/upper_arm", (l1, 0.0)))
    children = ("/bodyset/upper_arm", "/bodyset/forearm")
    for i, g in enumerate(GROUPS):
        points: list[str] = []
        wraps: list[tuple[str, int, int]] = []
        rest_length = 0.0
        on_upper: list[tuple[float, float]] = []     # the points a bi-articular path has there
        for j in (0, 1):
            r = float(jl[i, j])
            if r == 0.0:
                continue
            rho, flexor = abs(r), r < 0
            lo, hi = ranges[j]
            phi_o, phi_i = _wrap_angles(flexor, lo, hi)
            frame, (cx, cy) = centres[j]
            d = POINT_RADII * rho
            wname = f"{g}_{'shoulder' if j == 0 else 'elbow'}_wrap"
            (wraps_ground if j == 0 else wraps_upper).append(_cylinder(wname, (cx, cy), rho))
            n0 = len(points) + 1                     # PathWrap ranges count points from 1
            p_in = (cx + d * math.cos(phi_o), cy + d * math.sin(phi_o))
            p_out = (d * math.cos(phi_i), d * math.sin(phi_i))
            points.append(_point(f"{g}_{j}_in", frame, p_in))
            points.append(_point(f"{g}_{j}_out", children[j], p_out))
            on_upper.append(p_out if j == 0 else p_in)
            wraps.append((wname, n0, n0 + 1))
            q_r = (q1r, q2r)[j]
            sep = (phi_o - phi_i - q_r) if flexor else (phi_i + q_r - phi_o)
            rest_length += _wrapped_length(rho, sep)
        if len(wraps) == 2:                          # the straight run along the upper arm
            rest_length += math.dist(on_upper[0], on_upper[1])
        path = _path(points, wraps)
        forces.append(f'<PathActuator name="{g}"><appliesForce>true</appliesForce>'
                      f"<optimal_force>{p.alpha_n[i]:.17g}</optimal_force>"
                      f"<min_control>0</min_control><max_control>1</max_control>"
                      f"{path}</PathActuator>")
        forces.append(f'<PathSpring name="{g}_passive"><appliesForce>true</appliesForce>'
                      f"<resting_length>{rest_length:.17g}</resting_length>"
                      f"<stiffness>{p.km_n_per_m[i]:.17g}</stiffness>"
                      f"<dissipation>0</dissipation>{path}</PathSpring>")
    doc = escape(params.to_json())

    def body(bname: str, mass: float, com: float, inertia: float, wraps: list[str]) -> str:
        wrap_set = (f"<WrapObjectSet><objects>{''.join(wraps)}</objects></WrapObjectSet>"
                    if wraps else "")
        return (f'<Body name="{bname}"><mass>{mass:.17g}</mass>'
                f"<mass_center>{_v(com, 0, 0)}</mass_center>"
                f"<inertia>{_v(1e-4, inertia, inertia, 0, 0, 0)}</inertia>{wrap_set}</Body>")

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
        f'<Ground name="ground"><WrapObjectSet><objects>{"".join(wraps_ground)}</objects>'
        "</WrapObjectSet></Ground>"
        "<BodySet><objects>"
        f"{body('upper_arm', m1, c1, i1, wraps_upper)}"
        f"{body('forearm', m2, c2, i2, [])}"
        "</objects></BodySet>"
        "<JointSet><objects>"
        f"{pin('shoulder', 'ground', 0.0, 'upper_arm', COORDINATES[0], s_lo, s_hi, q1r)}"
        f"{pin('elbow', 'upper_arm', l1, 'forearm', COORDINATES[1], e_lo, e_hi, q2r)}"
        "</objects></JointSet>"
        f"<ForceSet><objects>{''.join(forces)}</objects></ForceSet>"
        f"<MarkerSet><objects><Marker name=\"handle\"><socket_parent_frame>/bodyset/forearm"
        f"</socket_parent_frame><location>{_v(l2, 0, 0)}</location></Marker></objects>"
        "</MarkerSet>"
        "</Model></OpenSimDocument>\n")
