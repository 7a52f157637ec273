"""Serving policies over the wire protocol (:mod:`molmo_lerobot.protocol`): the server, its
request checks, and the per-run server of ``policy.serve=true``."""
