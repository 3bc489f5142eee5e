"""One router per resource; :func:`wz_gateway.app.create_app` includes them in this order."""
