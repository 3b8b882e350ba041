"""The Python client of the nonholonomic API and the ``nonholonomic`` command line.

>>> from nonholonomic_client import Client, ApiError
"""

from nonholonomic_client.api import DEFAULT_URL, Client
from nonholonomic_client.errors import ApiError, JobFailed
from nonholonomic_client.progress import ProgressBar

__all__ = ["DEFAULT_URL", "ApiError", "Client", "JobFailed", "ProgressBar"]
