"""Remote assessment: the clinician's robot and the patient's robot joined by a delayed link.

::

    clinician's robot ─ renderer ─ ClinicianPort ═══ UDP ═══ PatientPort ─ patient's robot ─ arm
       (station)        (safety)    (passivity)   (sealed,   (passivity)    (safety, force
                                                   delay…)                    sensor)

* :mod:`~haptic.remote.wire` — the datagrams: sequence numbers, timestamps, every byte after
  the handshake sealed (AES-256-GCM), the replay window; the key file;
* :mod:`~haptic.remote.handshake` — fresh values from both sites, the session's keys through
  X25519 and HKDF, the clinician's proof before the patient's site accepts anything;
* :mod:`~haptic.remote.channel` — UDP or in-memory transport, the peer's address pinned,
  injected delay/jitter/loss, one site's endpoint (lockstep, round trip and loss measured);
* :mod:`~haptic.remote.config` — the settings of a site and of its end of the link;
* :mod:`~haptic.remote.passivity` — observer, energy tank and controller of each port;
* :mod:`~haptic.remote.plausible` — what a site accepts of its peer's STATEs;
* :mod:`~haptic.remote.supervision` — what both ends share: readiness, watchdog, the gain's
  ramps, the peer's end, events in words;
* :mod:`~haptic.remote.ports` — each end's tick: clutch, passivity, the patient's servo;
  :mod:`~haptic.remote.linklog` its per-tick log; :mod:`~haptic.remote.account` a session's
  account in words;
* :mod:`~haptic.remote.environment` — the link as the renderer's virtual arm;
* :mod:`~haptic.remote.patient_site`, :mod:`~haptic.remote.clinician_site` — the two sites
  (``fieldbank haptic remote patient|clinician``), each driving its robot through the robot
  port (:mod:`haptic.port`) and judging it with the safety monitor (:mod:`haptic.monitor`);
* :mod:`~haptic.remote.tap` — the link's rows for the station's process;
* :mod:`~haptic.remote.simulate` — both sites in one process (benchmark, simulated trainee).

Positions cross the link in the shoulder frame of the patient; forces are the force of the
patient's hand on the patient's handle, displayed on the clinician's handle.
"""
