"""The `wz` operator command."""
