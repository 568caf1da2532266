"""Shared test configuration.

PostgreSQL tests (marker ``postgres``) use the server at ``FIELDBANK_TEST_PG_URL``. Without it
they are skipped on a developer machine; with ``FIELDBANK_REQUIRE_PG=1`` (set by scripts/test,
which starts a real server) a missing URL is an error, so CI never skips them silently.
"""

from __future__ import annotations

import os

import pytest
from hypothesis import HealthCheck, settings

settings.register_profile(
    "fieldbank", deadline=None, suppress_health_check=[HealthCheck.too_slow], derandomize=True
)
settings.load_profile("fieldbank")


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    if os.environ.get("FIELDBANK_TEST_PG_URL"):
        return
    required = os.environ.get("FIELDBANK_REQUIRE_PG") == "1"
    for item in items:
        if "postgres" in item.keywords:
            if required:
                raise pytest.UsageError(
                    "FIELDBANK_REQUIRE_PG=1 but FIELDBANK_TEST_PG_URL is unset: "
                    "start a server with scripts/pg-test-server."
                )
            item.add_marker(pytest.mark.skip(reason="FIELDBANK_TEST_PG_URL not set"))
