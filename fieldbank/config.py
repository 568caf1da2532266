"""Configuration: every setting with the place its value came from.

A value comes from the first of, in this order:

1. a command-line flag (``--db``, ``--robot``, ``--scheduler``, ...), passed in by the caller;
2. an environment variable (``FIELDBANK_DB``, ``FIELDBANK_HOME``, ...);
3. the configuration file ``fieldbank.toml``: the file named by ``FIELDBANK_CONFIG``, else
   ``fieldbank.toml`` in the current directory, else in the user configuration directory
   (platformdirs; ``~/.config/fieldbank/fieldbank.toml`` on Linux) - the first found, read
   with :mod:`tomllib`;
4. the built-in default.

:func:`setting` returns a :class:`Setting` (value and source) and is what the rest of fieldbank
calls; ``fieldbank config show`` prints every one. The file is checked whole when read: an
unknown key (a typo would otherwise be ignored without a word), a value of the wrong type or a
file that is not TOML is a :class:`~fieldbank.errors.ConfigError` naming the file and the key.

An example file (every key optional)::

    db = "postgresql+psycopg://clinic@db.example/fieldbank"   # database URL
    home = "~/fieldbank-data"           # data directory (embedded database, traces, socket)
    arrays = "/srv/fieldbank/arrays"    # array store of a SQLite database
    robot = "/dev/ttyUSB0"              # the robot 'haptic serve' drives
    haptic_socket = "/run/fieldbank/haptic.sock"

    [scheduler]                         # the Dask cluster of the batch commands
    address = "tls://10.0.0.5:8786"     # (or, with no other scheduler key: scheduler = "...")
    tls_ca = "~/.config/fieldbank/cluster/ca.pem"       # 'fieldbank cluster certs' makes
    tls_cert = "~/.config/fieldbank/cluster/client.pem" # these (docs/scale-out.md)
    tls_key = "~/.config/fieldbank/cluster/client-key.pem"

    [report]
    jobs = 2                            # worker processes of 'fieldbank report'
    no_date = false                     # leave the time of writing out of reports

    [ingest.limits]                     # as 'ingest --limit NAME=VALUE' (docs/formats.md)
    max_rows = 200000

Light on purpose (standard library and platformdirs): every command imports it.
"""

from __future__ import annotations

import os
import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import platformdirs

from fieldbank.errors import ConfigError
from fieldbank.redact import mask_url

FILE_NAME = "fieldbank.toml"
#: The embedded database's file in the data directory (when no ``db`` is set).
DEFAULT_DB_FILE = "fieldbank.sqlite3"
ENV_CONFIG = "FIELDBANK_CONFIG"
#: Address schemes of a Dask scheduler (``dask.distributed`` comms).
SCHEDULER_SCHEMES = ("tcp", "tls", "ws", "wss", "ucx")
#: ``SCHEME://HOST:PORT`` of a Dask scheduler (HOST a name, an IPv4 address or [IPv6]).
SCHEDULER_RE = re.compile(r"([a-z]+)://(\[[0-9A-Fa-f:.]+\]|[A-Za-z0-9.-]+):([0-9]{1,5})")


def _text(v: object) -> str:
    if not isinstance(v, str) or not v.strip():
        raise ValueError("a non-empty string")
    return v


def _path(v: object) -> Path:
    return Path(_text(v)).expanduser()


def _scheduler(v: object) -> str:
    text = _text(v).strip()
    m = SCHEDULER_RE.fullmatch(text)
    if m is None and "@" in text:
        raise ValueError("a Dask scheduler address SCHEME://HOST:PORT without a user or a "
                         "password: a scheduler takes neither (a cluster admits its members by "
                         "their TLS certificates, docs/scale-out.md)")
    if m is None or m.group(1) not in SCHEDULER_SCHEMES or not 0 < int(m.group(3)) < 65536:
        raise ValueError("a Dask scheduler address tcp://HOST:PORT (e.g. tls://10.0.0.5:8786, "
                         "the address 'dask scheduler' prints; schemes "
                         f"{', '.join(SCHEDULER_SCHEMES)})")
    return text


def _jobs(v: object) -> int:
    if isinstance(v, int) and not isinstance(v, bool):
        n = v
    elif isinstance(v, str) and v.strip().isdigit():
        n = int(v)
    else:
        n = 0
    if n < 1:
        raise ValueError("a whole number of processes >= 1")
    return n


def _flag(v: object) -> bool:
    if isinstance(v, bool):
        return v
    if isinstance(v, str) and v.strip().lower() in ("1", "true", "yes", "0", "false", "no"):
        return v.strip().lower() in ("1", "true", "yes")
    raise ValueError("true or false")


def _limits(v: object) -> dict[str, float]:
    """``{name: number}`` from the file, or ``NAME=VALUE,...`` from the variable; the names
    and ranges are checked by :class:`fieldbank.ingest.limits.IngestLimits`."""
    if isinstance(v, str):
        out: dict[str, float] = {}
        for item in (p for p in v.split(",") if p.strip()):
            name, sep, value = item.partition("=")
            try:
                out[name.strip()] = float(value)
            except ValueError:
                raise ValueError(f"NAME=VALUE items; {item.strip()!r} is not one") from None
            if not sep:
                raise ValueError(f"NAME=VALUE items; {item.strip()!r} is not one")
        return out
    if isinstance(v, Mapping) and all(isinstance(x, (int, float)) and not isinstance(x, bool)
                                      for x in v.values()):
        return {str(k): float(x) for k, x in v.items()}
    raise ValueError("a table of limit = number")


@dataclass(frozen=True)
class Key:
    """One setting: its name (dotted for a table), variable, flag, check and default."""

    name: str
    help: str
    convert: Callable[[object], Any]
    env: str | None = None
    flag: str | None = None
    default: Callable[[], Any] | None = None
    #: how the value is shown (URLs without their secrets)
    show: Callable[[Any], str] = str
    #: what holds when nothing sets it and there is no default value
    unset: str = "(not set)"


def _default_home() -> Path:
    return Path(platformdirs.user_data_dir("fieldbank", appauthor=False))


#: Every setting fieldbank reads, in the order ``config show`` lists them.
KEYS: dict[str, Key] = {k.name: k for k in (
    Key("home", "data directory: the embedded database, traces, the control socket", _path,
        "FIELDBANK_HOME", None, _default_home),
    Key("db", "database URL (default: fieldbank.sqlite3 in the data directory)", _text,
        "FIELDBANK_DB", "--db", None, mask_url),
    Key("arrays", "array store of a SQLite database (default: beside its file)", _path,
        "FIELDBANK_ARRAYS", unset="(beside the SQLite file)"),
    Key("robot", "the robot 'haptic serve' drives: a port or URL (no default: serve asks)",
        _text, "FIELDBANK_ROBOT", "--robot", None, mask_url, "(none: give --robot)"),
    Key("scheduler", "Dask scheduler of the batch commands, tls://HOST:PORT (tcp:// only on "
        "this machine's loopback; default: local worker processes)", _scheduler,
        "FIELDBANK_SCHEDULER", "--scheduler", unset="(none: local worker processes)"),
    Key("scheduler.tls_ca", "the cluster's CA certificate, PEM (a tls:// scheduler)", _path,
        "FIELDBANK_SCHEDULER_TLS_CA", "--tls-ca"),
    Key("scheduler.tls_cert", "this client's certificate, PEM (a tls:// scheduler)", _path,
        "FIELDBANK_SCHEDULER_TLS_CERT", "--tls-cert"),
    Key("scheduler.tls_key", "this client's private key, PEM, readable by its owner only",
        _path, "FIELDBANK_SCHEDULER_TLS_KEY", "--tls-key"),
    Key("scheduler.insecure", "accept a tcp:// scheduler beyond the loopback: anyone who "
        "reaches it can run code on the workers", _flag, "FIELDBANK_INSECURE_SCHEDULER",
        "--insecure-scheduler", lambda: False),
    Key("haptic_socket", "control socket of a running renderer (default: haptic.sock in the "
        "data directory)", _path, "FIELDBANK_HAPTIC_SOCKET", "--socket",
        unset="(haptic.sock in home)"),
    Key("report.jobs", "worker processes of 'fieldbank report' (default: the cores "
        "available)", _jobs, "FIELDBANK_REPORT_JOBS", "--jobs",
        unset="(the cores available)"),
    Key("report.no_date", "leave the time of writing out of reports", _flag,
        "FIELDBANK_REPORT_NO_DATE", "--no-date", lambda: False),
    Key("ingest.limits", "ingest limits NAME=VALUE (docs/formats.md)", _limits,
        "FIELDBANK_INGEST_LIMITS", "--limit", dict,
        lambda v: ", ".join(f"{k}={x:g}" for k, x in v.items()) or "(the built-in limits)"),
)}


@dataclass(frozen=True)
class Setting:
    """A setting's value and where it came from.

    Attributes
    ----------
    name : str
    value : object
        Converted (a Path, an int, ...); None when nothing sets it and it has no default.
    source : str
        'flag --db', 'variable FIELDBANK_DB', 'file /path/fieldbank.toml' or 'default'.
    """

    name: str
    value: Any
    source: str

    @property
    def shown(self) -> str:
        """The value as it may be printed (URLs without secrets); '(not set)' for None."""
        key = KEYS[self.name]
        return key.unset if self.value is None else key.show(self.value)

    def to_dict(self) -> dict[str, Any]:
        return {"name": self.name, "value": None if self.value is None else self.shown,
                "source": self.source, "help": KEYS[self.name].help}


def config_file() -> Path | None:
    """The configuration file in force: ``FIELDBANK_CONFIG``, else ``./fieldbank.toml``, else
    the user configuration directory's; None when there is none."""
    named = os.environ.get(ENV_CONFIG)
    if named:
        p = Path(named).expanduser()
        if not p.is_file():
            raise ConfigError(f"{ENV_CONFIG}={named}: no such file.")
        return p
    for p in search_path():
        if p.is_file():
            return p
    return None


#: Other names a file may give a setting: the address inside the ``[scheduler]`` table (a TOML
#: file cannot hold both ``scheduler = "..."`` and a ``[scheduler]`` table).
FILE_ALIASES = {"scheduler.address": "scheduler"}


def shown_raw(raw: object) -> str:
    """A value as typed, for a message: URL secrets masked (:func:`mask_url`)."""
    return repr(mask_url(raw)) if isinstance(raw, str) else repr(raw)


def search_path() -> list[Path]:
    """Where ``fieldbank.toml`` is looked for, in order."""
    return [Path.cwd() / FILE_NAME,
            Path(platformdirs.user_config_dir("fieldbank", appauthor=False)) / FILE_NAME]


def _flatten(doc: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    out: dict[str, Any] = {}
    for k, v in doc.items():
        name = f"{prefix}{k}"
        table = isinstance(v, Mapping) and any(n.startswith(name + ".") for n in KEYS)
        if name in KEYS and not table:
            out[name] = v
        elif isinstance(v, Mapping):
            out.update(_flatten(v, name + "."))
        else:
            out[FILE_ALIASES.get(name, name)] = v
    return out


def read_file(path: Path) -> dict[str, Any]:
    """The settings of a configuration file, converted and checked, by dotted name."""
    import tomllib  # only when there is a file: a command without one starts without the parser

    try:
        doc = tomllib.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read ({exc.strerror}).") from None
    except UnicodeDecodeError:
        raise ConfigError(f"{path}: not UTF-8 text.") from None
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{path}: not valid TOML ({exc}).") from None
    out: dict[str, Any] = {}
    for name, raw in _flatten(doc).items():
        key = KEYS.get(name)
        if key is None:
            raise ConfigError(f"{path}: unknown setting {name!r}; the settings are "
                              f"{', '.join(KEYS)}.")
        try:
            out[name] = key.convert(raw)
        except ValueError as exc:
            raise ConfigError(f"{path}: {name} must be {exc}; got {shown_raw(raw)}.") from None
    return out


def setting(name: str, flag: object = None) -> Setting:
    """The value of setting ``name`` and its source (module docstring); ``flag`` is the
    command-line value when the command has that option and it was given."""
    key = KEYS[name]
    if flag is not None:
        try:
            return Setting(name, key.convert(flag), f"flag {key.flag or name}")
        except ValueError as exc:
            raise ConfigError(f"{key.flag or name} must be {exc}; got {shown_raw(flag)}."
                              ) from None
    if key.env:
        env = os.environ.get(key.env)
        if env and env.strip():
            try:
                return Setting(name, key.convert(env), f"variable {key.env}")
            except ValueError as exc:
                raise ConfigError(f"{key.env} must be {exc}; got {shown_raw(env)}."
                                  ) from None
    path = config_file()
    if path is not None:
        values = read_file(path)
        if name in values:
            return Setting(name, values[name], f"file {path}")
    return Setting(name, key.default() if key.default else None, "default")


def file_setting(name: str) -> Setting | None:
    """Setting ``name`` as the configuration file gives it (None: no file, or not in it);
    for settings that are layered rather than replaced (the ingest limits)."""
    path = config_file()
    if path is None:
        return None
    values = read_file(path)
    return Setting(name, values[name], f"file {path}") if name in values else None


def settings(flags: Mapping[str, object] | None = None) -> list[Setting]:
    """Every setting in force, as :func:`setting` gives it (``flags``: name -> the command
    line's value). ``db`` unset is shown as the embedded database it then is."""
    flags = flags or {}
    out = [setting(name, flags.get(name)) for name in KEYS]
    for k, s in enumerate(out):
        if s.name == "db" and s.value is None:
            home = out[0]
            out[k] = Setting("db", f"sqlite:///{home.value / DEFAULT_DB_FILE}",
                             f"default: {DEFAULT_DB_FILE} in home (home from {home.source})")
    return out
