"""The cart's serial link and its emulation (docs/architecture.md maps the modules).

The pure framing (``dialect``, the bridge's channel map in ``bridge``) imports nothing of
cartctl's. The wire protocol is docs/serial-protocol.md.
"""
