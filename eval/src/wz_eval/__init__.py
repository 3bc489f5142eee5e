"""Evaluation of the pipeline against simulation truth (the ``wz eval*`` commands)."""
