"""How much delay each judgement tolerates, with where each number comes from.

Two kinds of figure (docs/remote.md):

* what people notice (BRIEF §15): a delay in a rendered damper is noticed from ≈ 15 ms, in a
  spring from ≈ 36 ms, in an inertia from ≈ 72 ms (Rank, Shi, Müller & Hirche 2010, "The
  influence of different haptic environments on time delay discrimination in force feedback",
  EuroHaptics, LNCS 6191). Velocity-dependent resistance (spasticity) is felt as a damper,
  position-dependent resistance (contracture, stiffness) as a spring;
* what the link does to a judgement: the simulated trainee's accuracy through a simulated
  link (``benchmarks/bench_remote_perception.py``; the accuracy-vs-delay figure): the largest
  delay at which naming the group, and naming the severity, stays within 10 percentage points
  of the trainee's accuracy without delay, and the confusions the link adds beyond it.

:func:`warnings` says, for a measured one-way delay and the judgement at hand, what the station
should warn about.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Tolerance:
    """One judgement's delay limit, s, and its source."""

    judgement: str
    limit_s: float
    why: str
    source: str


#: Rank et al. 2010 (BRIEF §15).
NOTICED: tuple[Tolerance, ...] = (
    Tolerance("velocity-dependent resistance (spasticity)", 0.015,
              "a delay in a damper is noticed from ≈ 15 ms", "Rank et al. 2010"),
    Tolerance("position-dependent resistance (stiffness, contracture)", 0.036,
              "a delay in a spring is noticed from ≈ 36 ms", "Rank et al. 2010"),
    Tolerance("the arm's inertia", 0.072,
              "a delay in an inertia is noticed from ≈ 72 ms", "Rank et al. 2010"),
)

#: The simulated trainee through a simulated link (benchmarks/bench_remote_perception.py,
#: 24 assessment trials per delay, direction blur 20°, size blur 0.1; docs/remote.md): the
#: largest one-way delay measured at which its accuracy stays within 10 points of no link, and
#: what it gets wrong beyond.
SIMULATED: dict[str, Tolerance] = {
    "group": Tolerance("the impaired group (shoulder, elbow, both)", 0.005,
                       "the simulated trainee named the group as well as without a link up to "
                       "5 ms one-way (88 %, 83 % without), in 67-71 % of trials from 15 to "
                       "100 ms and 54 % at 300 ms",
                       "simulated trainee, docs/remote.md"),
    "severity": Tolerance("the severity (very mild … severe)", 0.015,
                          "the simulated trainee judged the severity right in 92 % of trials at "
                          "15 ms (96 % without a link), 50 % at 50 ms, where it read half of the "
                          "very mild and mild arms as moderate or severe",
                          "simulated trainee, docs/remote.md"),
}


def judgement_at_hand(group_probability: float | None) -> str:
    """'group' until the group is settled (p ≥ 0.9), then 'severity'."""
    return "severity" if group_probability is not None and group_probability >= 0.9 \
        else "group"


def warnings(one_way_s: float, at_hand: str) -> list[dict[str, str | float]]:
    """What a delay of ``one_way_s`` puts in doubt, the judgement at hand first."""
    out: list[dict[str, str | float]] = []
    first = SIMULATED.get(at_hand)
    for tol in ([first] if first else []) + [t for k, t in SIMULATED.items() if k != at_hand] \
            + list(NOTICED):
        if one_way_s > tol.limit_s:
            out.append({"judgement": tol.judgement, "limit_ms": tol.limit_s * 1e3,
                        "why": tol.why, "source": tol.source,
                        "at_hand": tol is first})
    return out


def table() -> list[dict[str, str | float]]:
    """Every limit, for the station to show beside the delay."""
    return [{"judgement": t.judgement, "limit_ms": t.limit_s * 1e3, "why": t.why,
             "source": t.source} for t in (*SIMULATED.values(), *NOTICED)]
