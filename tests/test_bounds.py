"""One bounds check for every frozen configuration (fieldbank.validation.check_fields)."""

from __future__ import annotations

import re
from dataclasses import dataclass

import pytest

from fieldbank.errors import ParameterError
from fieldbank.evaluate.design import NoiseModel, Perception, ProbeLimits
from fieldbank.haptic.measure import MeasureConfig
from fieldbank.haptic.patient import PatientPlacement
from fieldbank.haptic.remote.clinician_site import AssessOptions
from fieldbank.haptic.rendererconfig import RendererConfig
from fieldbank.haptic.safety import SafetyConfig
from fieldbank.haptic.session import ScheduledSwitch
from fieldbank.haptic.simrobot import SimRobotConfig
from fieldbank.haptic.station.config import StationConfig
from fieldbank.haptic.station.launch import StationOptions
from fieldbank.haptic.trainee import TraineeMotion
from fieldbank.haptic.training import TrainingProtocol
from fieldbank.haptic.workspace.host import RobotSettings
from fieldbank.ingest.limits import IngestLimits
from fieldbank.validation import Interval, check_fields


@dataclass(frozen=True)
class _Config:
    rate_hz: object = 1000
    gain: object = 0.5


BOUNDS = {"rate_hz": Interval.whole(500, 4000, "Hz"), "gain": Interval(0.0, 1.0)}


def test_every_problem_in_one_message_and_whole_numbers_stay_whole() -> None:
    check_fields(_Config(), BOUNDS, what="loop setting")
    with pytest.raises(ParameterError) as err:
        check_fields(_Config(rate_hz=1000.5, gain=2.0), BOUNDS, what="loop setting")
    msg = str(err.value)
    assert ("The 'rate_hz' loop setting must be a whole number (an integer) in [500, 4000] Hz; "
            "got 1000.5") in msg
    assert "The 'gain' loop setting must be a finite number in [0, 1]; got 2.0 instead." in msg
    for bad in (1000.0, True, "1000", 499, 4001):
        with pytest.raises(ParameterError, match="'rate_hz' loop setting must be a"):
            check_fields(_Config(rate_hz=bad), BOUNDS, what="loop setting")
    check_fields(_Config(gain=float("nan")), BOUNDS, names=["rate_hz"])  # only those named
    assert Interval.whole(0, 50).describe() == "[0, 50]"


@pytest.mark.parametrize(("make", "fields_", "what"), [
    (lambda: RendererConfig(rate_hz=1000.0, crossfade_s=-1.0), ("rate_hz", "crossfade_s"),
     "renderer parameter"),
    (lambda: SafetyConfig(force_limit_n=0.0, rearm_ramp_s=-1.0),
     ("force_limit_n", "rearm_ramp_s"), "safety parameter"),
    (lambda: SimRobotConfig(handle_mass_kg=0.0, watchdog_ms=-1.0, seed=1.5),
     ("handle_mass_kg", "watchdog_ms", "seed"), "sim parameter"),
    (lambda: AssessOptions(force_sd_n=0.0), ("force_sd_n",), "assessment setting"),
    (lambda: TrainingProtocol(familiarisation_rounds=1.5, assessment_s=0.0),
     ("familiarisation_rounds", "assessment_s"), "training parameter"),
    (lambda: TraineeMotion(hold_s=-1.0, explore_s=0.0), ("hold_s", "explore_s"),
     "trainee parameter"),
    (lambda: IngestLimits(max_rows=2.5, max_force_n=0.0), ("max_rows", "max_force_n"),
     "ingest limit"),
    (lambda: Perception(force_jnd=0.0, floor_n=-1.0), ("force_jnd", "floor_n"),
     "perception parameter"),
    (lambda: NoiseModel(force_sd_n=0.0, length_sd=2.0), ("force_sd_n", "length_sd"),
     "noise parameter"),
    (lambda: ProbeLimits(max_speed_m_per_s=0.0, max_bulge=2.0),
     ("max_speed_m_per_s", "max_bulge"), "probe limit"),
    (lambda: MeasureConfig(rate_hz=100, state_wait_s=-1.0), ("rate_hz", "state_wait_s"),
     "measure setting"),
    (lambda: StationConfig("s", "c", "t", port=70000, frame_hz=0.0), ("port", "frame_hz"),
     "station setting"),
    (lambda: StationOptions(port=-1), ("port",), "station setting"),
    (lambda: PatientPlacement(float("nan"), float("inf")), ("shoulder_x_m", "shoulder_y_m"),
     "patient placement"),
    (lambda: ScheduledSwitch(-1.0, "B"), ("at_s",), "switch time"),
    (lambda: RobotSettings(None, "sqlite://", "t", rate_hz=8000, force_limit_n=0.0),
     ("rate_hz", "force_limit_n"), "workspace robot setting"),
])
def test_each_configuration_names_every_field_out_of_bounds(make, fields_, what) -> None:  # type: ignore[no-untyped-def]
    with pytest.raises(ParameterError) as err:
        make()
    for name in fields_:
        assert f"The '{name}' {what} must be a" in str(err.value), str(err.value)


def test_an_assessment_names_what_it_does_not_know() -> None:
    for make, words in (
            (lambda: AssessOptions(levels=("mild", "extreme")),
             "the assessment's severity is one of very mild, mild, moderate, severe; got "
             "'extreme'"),
            (lambda: AssessOptions(groups=("knee",)),
             "the assessment's muscle group is one of shoulder, elbow, biarticular; got 'knee'"),
            (lambda: AssessOptions(groups=(), unimpaired=False),
             "the assessment needs a candidate"),
            (lambda: AssessOptions(predictor="guess"),
             "the assessment's predictor is one of replay, rigid, static; got 'guess'")):
        with pytest.raises(ParameterError, match=re.escape(words)):
            make()
    assert AssessOptions(groups=(), unimpaired=True).to_dict()["groups"] == []


def test_a_station_view_is_one_of_the_two() -> None:
    for make in (lambda: StationOptions(view="sideways"),
                 lambda: StationConfig("s", "c", "t", view="sideways")):
        with pytest.raises(ParameterError, match="'view' station setting must be opposite or "
                                                 "behind; got 'sideways'"):
            make()
