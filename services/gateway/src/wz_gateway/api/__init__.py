"""The HTTP API: :mod:`.deps` (what a route asks for), :mod:`.errors` (problem answers),
:mod:`.middleware`, :mod:`.params` (shared query parameters), one router per resource in
:mod:`.routes`, all of them in order in :mod:`.main`; :func:`wz_gateway.app.create_app` puts
them together."""
