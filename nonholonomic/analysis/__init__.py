"""Dynamics beyond one trajectory's evidence: Poincaré sections (:mod:`.poincare`), Lyapunov
spectra (:mod:`.lyapunov`), states on a level set of the integrals (:mod:`.sampling`) and
ensembles cut into chunks (:mod:`.ensemble`). Pure computation, like the rest of the core: the
workers only fan chunks out and gather them.
"""
