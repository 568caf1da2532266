"""The clinician's station: a live picture of the virtual arm over the hidden robot (seed,
"Haptic display of limb neuro-mechanics"; BRIEF §12), with the before/after switch, A/B/X
blocks and the training protocol on one page.

How it never delays the 1 kHz loop::

    loop process                                   station process (nice, own interpreter)
    ─────────────                                  ──────────────────────────────────────
    Renderer.tick ──publish (≈1 µs, no lock)──►  snapshot (shared memory, seqlock)
                                                      │ read at 60 Hz
    control socket ◄──── switch / abx / train ────  aiohttp: page, WebSocket ◄──► browser
                                                      (127.0.0.1, per-session token)

- :mod:`haptic.snapshot` - the record the loop publishes each tick;
- :mod:`haptic.station.server` - the web server (page, WebSocket, token, blinding);
- :mod:`haptic.station.launch` - starting and stopping its process (:mod:`haptic.station.config`:
  what it is told);
- ``page.html``, ``station.js``, ``station.css`` - the page: plain HTML, canvas and script, no
  build step and nothing loaded from elsewhere.
"""

from fieldbank.haptic.station.config import StationConfig
from fieldbank.haptic.station.launch import StationOptions, StationProcess

__all__ = ["StationConfig", "StationOptions", "StationProcess"]
