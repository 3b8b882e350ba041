"""The routes of symbolic work: Theorem 1 for a system of one's own, a bracket to verify, and the
paper report (every claim of the paper checked in one job)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from nonholonomic_client.base import BaseClient


class SymbolicRoutes(BaseClient):
    """``/v1/hamiltonize``, ``/v1/brackets/verify`` and ``/v1/paper/*``; :class:`Client` has them all."""

    def hamiltonize_examples(self) -> dict[str, Any]:
        """``GET /v1/hamiltonize/examples``: worked examples of Theorem 1, ready to post.

        Returns
        -------
        dict
            ``{name: request}`` (Chaplygin's ball in Euler angles, Veselova's system).
        """
        return dict(self._json("GET", "/v1/hamiltonize/examples")["examples"])

    def hamiltonize(self, request: Mapping[str, Any]) -> dict[str, Any]:
        """``POST /v1/hamiltonize``: Theorem 1 for a 2-DOF generalized Chaplygin system.

        Parameters
        ----------
        request : dict
            ``{coordinates, velocities, L, a1, a2, b, symbols, parameters, ...}``: the Lagrangian and the
            gyroscopic terms as expressions (see :meth:`hamiltonize_examples`).

        Returns
        -------
        dict
            The integrability condition, the reducing multiplier N, S̄ = N·B, H̄, the bracket, and the
            check that the τ-flow is Hamiltonian, each with its verdict.

        Raises
        ------
        ApiError
            422 naming an expression the parser refuses; 503 when the symbolic pool is full or the work
            passed the machine's safety cap (not a verdict; ``retry_after`` says when to retry).
        """
        return dict(self._json("POST", "/v1/hamiltonize", json=request))

    def verify_bracket(self, request: Mapping[str, Any]) -> dict[str, Any]:
        """``POST /v1/brackets/verify``: antisymmetry, the Jacobi identity, Casimirs and rank of a bracket.

        Parameters
        ----------
        request : dict
            ``{variables, bracket, ...}``: the matrix of ``{x_i, x_j}`` as expressions.

        Returns
        -------
        dict
        """
        return dict(self._json("POST", "/v1/brackets/verify", json=request))

    def paper_claims(self) -> list[str]:
        """``GET /v1/paper/claims``: the ids of the claims the paper report checks.

        Returns
        -------
        list of str
        """
        return list(self._json("GET", "/v1/paper/claims")["claims"])

    def paper_report(self, claims: list[str] | None = None) -> str:
        """``POST /v1/paper/report``: check the paper's claims (all, or those given) in one job.

        Parameters
        ----------
        claims : list of str, optional
            Claim ids (see :meth:`paper_claims`); default every claim.

        Returns
        -------
        str
            The job id (wait with :meth:`wait`, read with :meth:`result` or :meth:`report_page`).
        """
        body = None if claims is None else {"claims": list(claims)}
        return str(self._json("POST", "/v1/paper/report", json=body)["id"])

    def report_page(self, job_id: str) -> str:
        """``GET /v1/paper/report/{id}``: the report as an HTML page.

        Parameters
        ----------
        job_id : str

        Returns
        -------
        str
            The HTML (a status page that reloads itself while the job runs).
        """
        return self._request("GET", f"/v1/paper/report/{job_id}").text
