"""Imported by the fork server only (a preload of :mod:`service.isolated`), never by the API: the symbolic
work every validation child would otherwise repeat is done once here, before any child is forked.

A child checking a request with user expressions (:mod:`service.validation`) needs each kind's own names
(:func:`nonholonomic.systems.own_names`, one definition per kind) and, for the balls on a surface, the
reduction check of :mod:`nonholonomic.systems.ball_on_quadric`: about 4 s of sympy, which would count
on every request's validation. The fork server pays it once, at the API's start-up.
"""

from __future__ import annotations

from nonholonomic.systems import SYSTEMS, ball_on_quadric, own_names
from workers.disk_memo import install_from_settings

install_from_settings()  # the children inherit it
ball_on_quadric.check_reduction()
for _kind in SYSTEMS:
    own_names(_kind)
