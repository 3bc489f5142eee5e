"""One router per resource (``router``, module level); :mod:`wz_gateway.api.main` includes
them in the order they are matched."""
