"""Remote assessment: the clinician's robot and the patient's robot joined by a delayed link.

::

    clinician's robot ─ renderer ─ ClinicianPort ═══ UDP ═══ PatientPort ─ patient's robot ─ arm
       (station)        (safety)    (passivity)   (auth,     (passivity)    (safety, force
                                                   delay…)                    sensor)

* :mod:`~haptic.remote.wire` — the datagrams: sequence numbers, timestamps, an HMAC on each,
  the replay window; the session key;
* :mod:`~haptic.remote.channel` — UDP or in-memory transport, injected delay/jitter/loss, one
  site's endpoint (authentication, lockstep, round trip and loss measured);
* :mod:`~haptic.remote.passivity` — observer, energy tank and controller of each port;
* :mod:`~haptic.remote.ports` — each end's tick: watchdog and ramps, clutch, passivity, the
  patient's servo, the per-tick log;
* :mod:`~haptic.remote.environment` — the link as the renderer's virtual arm;
* :mod:`~haptic.remote.patient_site`, :mod:`~haptic.remote.clinician_site` — the two sites
  (``fieldbank haptic remote patient|clinician``); :mod:`~haptic.remote.guard` the robot checks
  of the patient's site;
* :mod:`~haptic.remote.tap` — the link's rows for the station's process;
* :mod:`~haptic.remote.simulate` — both sites in one process (benchmark, simulated trainee).

Positions cross the link in the shoulder frame of the patient; forces are the force of the
patient's hand on the patient's handle, displayed on the clinician's handle.
"""
