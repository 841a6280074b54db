"""wott-hub driver plugin: XELA uSkin sensors through XELA's own ``xela_server`` (docs/skins.md).

``plugin`` holds the hooks; ``protocol`` the server's JSON messages and the sensor models,
``connection`` one WebSocket per server shared by its positions, ``driver`` one position.
"""
