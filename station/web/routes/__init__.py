"""The web application's routers, one per area: :mod:`.status` (status page, events, ``/api/status``),
:mod:`.runs` (``/api/runs``, start and abort), :mod:`.units` (unit page and plots, ``/api/units``, EEPROM
image), :mod:`.diagnosis` (a recording's diagnosis and its figure) and :mod:`.population`.

Each route gets the application's :class:`~station.web.context.WebContext` as a dependency
(:data:`station.web.context.Web`).
"""
