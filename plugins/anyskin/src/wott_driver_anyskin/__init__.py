"""wott-hub driver plugin: AnySkin and ReSkin magnetic skins (docs/skins.md).

``plugin`` holds the hooks; ``protocol`` the binary burst stream and its resync, ``boards`` where the
magnetometers sit on each board, ``driver`` the device.
"""
