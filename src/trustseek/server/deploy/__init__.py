"""The decision API: a robot's deploy sessions, from HTTP to the database.

``http`` (the routes, and ``decide``/``observe`` answered in plain ASGI in front of FastAPI),
``service`` (the sessions, without HTTP, refusing with ``server.errors``), ``store`` (the
statements on the database driver's own connection); each session's plan is ``server.plan``'s.
Nothing is imported here: import the module that holds what you need.
"""
