"""Flying the selector on real vehicles over MAVLink (``vo3d link``) and a whole scenario as
separate processes over MAVLink (``vo3d sitl``, a test harness). Needs the ``[link]`` extra
(pymavlink, pyproj), imported only when a link runs; ``docs/link.md`` is the user guide.

Modules: :mod:`~vo3d_opt.link.frames` (NED/ENU, geodetic with pyproj),
:mod:`~vo3d_opt.link.messages` (what is sent and read), :mod:`~vo3d_opt.link.transport`
(the connection, rejected packets), :mod:`~vo3d_opt.link.neighbors` (the neighbour table and
its safety rules), :mod:`~vo3d_opt.link.planning` (the selector and what it plans with),
:mod:`~vo3d_opt.link.loop` (the link), :mod:`~vo3d_opt.link.report` (its summary),
:mod:`~vo3d_opt.link.vehicle` (the simulated vehicle), :mod:`~vo3d_opt.link.router`,
:mod:`~vo3d_opt.link.faults`, :mod:`~vo3d_opt.link.sitl` and
:mod:`~vo3d_opt.link.sitl_record` (the harness), :mod:`~vo3d_opt.link.command` (the CLI).
"""
