"""``fieldbank serve``: the clinic's workspace - patients, the plan composer and the robot in
one page, behind accounts (``fieldbank users``).

The command composes the workspace from its three parts - the core's routes (patients, maps,
fits, models, the audit log), the interventions' plan composer and the haptic wing's robot
view - handing the composer the robot through the core's seam, and serves it; the parts never
import each other.
"""

from __future__ import annotations

import click

from fieldbank.cli.options import db_option, log_info_to_stderr, open_db, say
from fieldbank.config import setting


@click.command("serve")
@click.option("--host", default="127.0.0.1", show_default=True,
              help="Address to bind; beyond the loopback only with --tls-cert and --tls-key.")
@click.option("--port", type=click.IntRange(0, 65535), default=8470, show_default=True,
              help="Port (0: any free port).")
@click.option("--tls-cert", type=click.Path(dir_okay=False), default=None,
              help="PEM certificate (chain) for HTTPS.")
@click.option("--tls-key", type=click.Path(dir_okay=False), default=None,
              help="PEM private key of the certificate.")
@click.option("--robot", default=None,
              help="The robot 'Feel it' renders on (a port URL, as 'haptic serve --robot'); "
                   "default: FIELDBANK_ROBOT, else robot in fieldbank.toml, else the "
                   "simulated robot.")
@db_option
def serve(host: str, port: int, tls_cert: str | None, tls_key: str | None, robot: str | None,
          db_url: str | None) -> None:
    """Serve the workspace: log in, find a patient, compose a plan, feel it on the robot."""
    from fieldbank.haptic.session import default_trace_dir
    from fieldbank.haptic.workspace.host import RendererHost, RobotSettings
    from fieldbank.haptic.workspace.view import RobotViewRoutes
    from fieldbank.interventions.workspace import ComposerRoutes
    from fieldbank.web.app import make_app
    from fieldbank.web.core_api import CoreRoutes
    from fieldbank.web.server import ServeConfig, run

    config = ServeConfig(host, port, tls_cert, tls_key)  # refused here, before anything binds
    config.ssl_context()
    log_info_to_stderr()
    db = open_db(db_url)
    if not db.list_users():
        say("no accounts yet: add one with 'fieldbank users add NAME --role clinician'")
    url = db.engine.url.render_as_string(hide_password=False)  # to the renderer, on its stdin
    host_ = RendererHost(RobotSettings(setting("robot", robot).value, url,
                                       str(default_trace_dir())))
    app = make_app(db, [CoreRoutes(), ComposerRoutes(robot=host_), RobotViewRoutes(host_)],
                   secure=config.tls)
    try:
        run(config, app, lambda url: say(f"workspace: {url} (Ctrl-C stops)"))
    finally:
        host_.close()
        db.close()
