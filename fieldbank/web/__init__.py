"""The workspace's web core (``fieldbank serve``): accounts at the door, routes behind it.

* :mod:`~fieldbank.web.routes` - the seam: :class:`Route`, :class:`RouteProvider`,
  :class:`Call` (the request, its caller, a database writing as the caller), :class:`ApiError`;
* :mod:`~fieldbank.web.app` - :func:`make_app`: who is asking (session cookie or bearer
  token), may they, CSRF, the audit actor, JSON errors, security headers, the page shell and
  its listed assets, login and logout, the OpenAPI document;
* :mod:`~fieldbank.web.accounts` - roles and permissions, Argon2id passwords, API tokens;
* :mod:`~fieldbank.web.sessions` - sessions, CSRF tokens, the login throttle (in memory);
* :mod:`~fieldbank.web.core_api` - the core's routes: patients, sessions, maps (figures),
  fits, models, ingest, the audit log;
* :mod:`~fieldbank.web.openapi` - the OpenAPI 3.1 document made from the routes;
* :mod:`~fieldbank.web.robot` - :class:`RobotSeam`: what "Feel it" asks of a renderer;
* :mod:`~fieldbank.web.server` - binding (loopback, or TLS beyond it) and running;
* ``index.html``, ``app.js``, ``app.css`` - the page.

The plan composer (:mod:`fieldbank.interventions.workspace`) and the robot view
(:mod:`fieldbank.haptic.workspace`) are providers the command line adds; this package imports
neither.
"""
