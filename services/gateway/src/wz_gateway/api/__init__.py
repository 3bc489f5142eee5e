"""The HTTP API: :mod:`.deps` (what a route asks for), :mod:`.errors` (problem answers),
:mod:`.middleware`, :mod:`.params` (shared query parameters) and one router per resource in
:mod:`.routes`; :func:`wz_gateway.app.create_app` puts them together."""
