"""fieldbank's Dask settings (``dask.yaml`` beside the cluster's certificates): Dask knows
every key and its default is the one recorded; Dask reads the file when ``DASK_CONFIG`` names
it and not otherwise; a user's ``DASK_…`` variable still wins; and a real ``dask worker``
process started as docs/scale-out.md says runs without the profiler and with the slower
timers, while one started without the variable keeps Dask's defaults."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
import yaml

from fieldbank.clustercerts import CertOptions, write_certs
from fieldbank.clusterconfig import CONFIG_FILE, SETTINGS, as_nested, dask_yaml

BIN = Path(sys.executable).parent
# glibc's variables a nanny sets for the worker it starts
MALLOC = ("MALLOC_TRIM_THRESHOLD_", "MALLOC_MMAP_THRESHOLD_")
# What a fresh process sees for each key, as JSON (Dask parses "500ms" at use, not here).
READ = ("import json, dask, distributed; print(json.dumps({k: dask.config.get(k, None) for k in "
        + repr([s.key for s in SETTINGS]) + "}))")


def _clean_env(**extra: str) -> dict[str, str]:
    """This process's environment without any DASK_ variable and without glibc's MALLOC_
    ones (a nanny started inside this process by another test leaves Dask's own there, and a
    variable already in the environment wins over Dask's configuration), plus ``extra``."""
    env = {k: v for k, v in os.environ.items() if not k.startswith(("DASK_", *MALLOC))}
    env["HOME"] = os.environ.get("HOME", "/nonexistent")
    env.update(extra)
    return env


def _seen(env: dict[str, str]) -> dict[str, object]:
    out = subprocess.run([sys.executable, "-c", READ], env=env, capture_output=True, text=True,
                         check=True)
    return dict(json.loads(out.stdout))


@pytest.fixture(scope="module")
def certs(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_certs(tmp_path_factory.mktemp("c") / "certs", CertOptions()).out_dir


def test_the_file_holds_every_setting_and_nothing_else() -> None:
    text = dask_yaml()
    assert yaml.safe_load(text) == as_nested()
    assert sum(1 for line in text.splitlines() if line.lstrip().startswith("# Dask's default")) \
        == len(SETTINGS)
    assert len({s.key for s in SETTINGS}) == len(SETTINGS)
    for s in SETTINGS:  # each changes something, and says what it costs
        assert s.value != s.dask_default and len(s.cost) > 40, s.key


def test_dask_reads_the_file_only_when_asked_and_a_users_variable_wins(certs: Path) -> None:
    defaults = _seen(_clean_env())
    # Dask's own, as recorded
    assert defaults == {s.key: s.dask_default for s in SETTINGS}
    path = str(certs / CONFIG_FILE)
    assert _seen(_clean_env(DASK_CONFIG=path)) == {s.key: s.value for s in SETTINGS}
    first = SETTINGS[0]
    mine = _seen(_clean_env(DASK_CONFIG=path, **{first.env_name: repr(first.dask_default)}))
    assert mine[first.key] == first.dask_default
    assert all(mine[s.key] == s.value for s in SETTINGS[1:])
    for s in SETTINGS:  # each variable alone sets its key alone (the benchmark)
        alone = _seen(_clean_env(**{s.env_name: s.env_value}))
        assert alone == {**defaults, s.key: s.value}, s.key


@pytest.fixture
def workers(tmp_path: Path) -> Iterator[dict[str, object]]:
    """A plain-TCP scheduler on the loopback and two ``dask worker`` processes, one started
    with ``DASK_CONFIG`` naming the file and one without; yields what each worker runs."""
    from distributed import Client

    (tmp_path / CONFIG_FILE).write_text(dask_yaml())
    sched_file = tmp_path / "scheduler.json"
    procs = [subprocess.Popen(
        [str(BIN / "dask"), "scheduler", "--host", "127.0.0.1", "--port", "0",
         "--no-dashboard", "--scheduler-file", str(sched_file)], env=_clean_env(),
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)]
    try:
        for name, extra in (("quiet", {"DASK_CONFIG": str(tmp_path / CONFIG_FILE)}),
                            ("default", {})):
            procs.append(subprocess.Popen(
                [str(BIN / "dask"), "worker", "--scheduler-file", str(sched_file),
                 "--nthreads", "1", "--no-dashboard", "--name", name],
                env=_clean_env(**extra), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
        for _ in range(600):  # the scheduler writes its address once it listens
            if sched_file.exists() or procs[0].poll() is not None:
                break
            time.sleep(0.5)
        assert sched_file.exists(), "the scheduler did not start"
        with Client(scheduler_file=str(sched_file), timeout=120,
                    set_as_default=False) as client:
            client.wait_for_workers(2, timeout=300)

            def state(dask_worker: object) -> dict[str, object]:
                pcs = dask_worker.periodic_callbacks  # type: ignore[attr-defined]
                return {"name": dask_worker.name,  # type: ignore[attr-defined]
                        "callbacks": {k: pcs[k].callback_time for k in pcs},
                        "environ": {k: os.environ.get(k) for k in MALLOC}}

            got = client.run(state)
        yield {v["name"]: {**v["callbacks"], **v["environ"]} for v in got.values()}
    finally:
        for p in reversed(procs):
            p.terminate()
        for p in procs:
            try:
                p.wait(30)
            except subprocess.TimeoutExpired:
                p.kill()


@pytest.mark.slow
def test_a_worker_started_with_the_file_runs_quieter_and_one_without_is_unchanged(
        workers: dict[str, dict[str, float]]) -> None:
    quiet, default = workers["quiet"], workers["default"]
    # Dask's defaults, milliseconds: the profiler every 10, the tick every 20, the system
    # monitor every 500, the memory monitor every 100
    assert default["profile"] == 10 and default["tick"] == 20
    assert default["monitor"] == 500 and default["memory_monitor"] == 100
    assert "profile" not in quiet and "profile-cycle" not in quiet
    assert quiet["tick"] == 500 and quiet["monitor"] == 2000
    assert quiet["memory_monitor"] == 500
    # the worker's process started with the memory thresholds of the file, and Dask's own
    # trim threshold (which fixes glibc's mmap threshold at 128 kB) without it
    assert quiet["MALLOC_TRIM_THRESHOLD_"] == "67108864"
    assert quiet["MALLOC_MMAP_THRESHOLD_"] == "33554432"
    assert default["MALLOC_TRIM_THRESHOLD_"] == "65536"
    assert default["MALLOC_MMAP_THRESHOLD_"] is None
