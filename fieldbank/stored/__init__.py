"""What the database holds, known without SQLAlchemy: the light side of the field database.

:mod:`fieldbank.storage` is the database itself - SQLAlchemy's ORM, the migrations, the array
store, the integrity check - and the one place that writes. This package is what can be known
or read without loading any of that, for the commands that must start at once:

    records.py     the records the list commands read (PatientInfo, StoredMap, ModelEntry,
                   PlanRecord, JobRunRecord, JobRecord; fieldbank.storage returns them too),
                   the job kinds and states
    revisions.py   the schema revisions this program knows, read from the migration files
    location.py    where the database is: the URL in force and where it came from, a SQLite
                   file, a PostgreSQL URL's connection arguments as SQLAlchemy makes them, the
                   URL as messages show it, the refusal of a missing file
    words.py       the messages for a patient or a batch run the database does not hold
    listing.py     Listing: what the list commands read, through sqlite3 or psycopg alone, on
                   a database at head (else the caller opens fieldbank.storage.Database)

Imports here are the standard library, platformdirs (through fieldbank.config) and the light
core modules; psycopg is imported when a server database is listed. Nothing here imports
fieldbank.storage (tests/test_cli_startup.py checks what the list commands load).
"""
