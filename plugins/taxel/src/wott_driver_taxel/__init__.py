"""wott-hub driver plugin: serial taxel arrays (docs/taxel-protocol.md).

``plugin`` holds the hooks; ``protocol`` the wire formats, ``reader`` the
serial link, ``simulator`` a board on a pty, ``compliance`` pressure <-> depth.
"""
