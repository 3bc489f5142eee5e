"""Shared library of the work-zone stack: messages, keys, bus, settings, site, time."""
