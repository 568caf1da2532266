"""fieldbank: force-field database and intervention what-if service for hypertonic arms.

Everything installs under this one name. The repository's top-level folders are its layers::

    fieldbank/       fieldbank            core: arm model, maps, severity, storage, ingest,
    migrations/      fieldbank.migrations     fitting, evaluation of a compiled arm
          ^                                  ^
    interventions/   fieldbank.interventions what-if, plans, reports     (never imports haptic)
    haptic/          fieldbank.haptic        robot link, 1 kHz loop, station (never imports
          ^                                  ^                            interventions)
    cli/             fieldbank.cli           click only: options -> one library call -> output

The layer rule: imports run one way, up the picture. The core imports nothing from
interventions, haptic or cli; interventions and haptic import the core and never each other;
only the command line imports all three. No import inside a function gets around it: library
modules import project modules at module level, so a cycle shows as an error, not as a hidden
function-level import. ``tests/test_layers.py`` checks every import of every module.
Where new code goes: ``docs/architecture.md``.
"""
