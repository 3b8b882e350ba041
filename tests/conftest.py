"""Test-wide settings.

Hypothesis runs derandomized under CI (``CI`` set): the same examples every run, so a red CI is
reproducible and no new counterexample's shrinking can blow the time limit. Locally it explores.
"""

from __future__ import annotations

import os

from hypothesis import settings

settings.register_profile("ci", derandomize=True, deadline=None, print_blob=True)
settings.register_profile("dev", deadline=None, print_blob=True)
settings.load_profile("ci" if os.environ.get("CI") else "dev")
