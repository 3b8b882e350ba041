"""The Python client of the nonholonomic API and the ``nonholonomic`` command line.

>>> from client import Client, ApiError
"""

from client.api import DEFAULT_URL, Client
from client.errors import ApiError, JobFailed
from client.progress import ProgressBar

__all__ = ["DEFAULT_URL", "ApiError", "Client", "JobFailed", "ProgressBar"]
