"""The decision API: a robot's deploy sessions, from HTTP to the database.

* ``http``: the one answer of ``decide`` and ``observe`` (``answer``) and the plain-ASGI front
  that serves it (``DeployFront``); ``routes``: the FastAPI routes (opening a session, its
  state, and the bodies the front hands on);
* ``service``: the sessions, independent of HTTP (``create_deploy``, ``deploy_decide``,
  ``deploy_observe``), refusing with the server's domain errors (``server.errors``);
* ``server.plan``: a session's task, model and policy with ``PolicyRunner``'s step (``PolicyPlan``,
  as a study block's), shared per content (``Plans``, owned by the application as ``app.state.deploy_plans``);
* ``store``: the statements on the database driver's own connections (``DeployStore``,
  ``app.state.deploy_store``); what they remember is bounded by ``server.cache.Bounded``.

Nothing is imported here: import the module that holds what you need.
"""
