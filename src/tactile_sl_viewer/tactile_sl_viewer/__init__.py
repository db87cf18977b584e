"""tactile-sl viewer: the decoder's outputs live in a browser (aiohttp page + WebSocket)."""
