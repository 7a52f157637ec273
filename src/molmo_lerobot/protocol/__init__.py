"""openpi-compatible policy wire protocol: msgpack + numpy codec, websocket client and server."""

from molmo_lerobot.protocol.codec import CodecError, packb, unpackb

__all__ = ["CodecError", "packb", "unpackb"]
