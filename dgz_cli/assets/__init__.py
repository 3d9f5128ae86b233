"""`dgz assets fetch`: build an asset root (``hands/``, ``objects/ycb45/``) from pinned upstream archives.

:mod:`.registry` reads the shipped registry (which file of which upstream archive, at which commit, lands
where, with its sha256); :mod:`.fetch` downloads (pooch, resumable, progress bar), extracts into a staging
folder, verifies every file and moves each verified unit (``hands/<hand>``, ``objects/ycb45``) into place
with one rename. A layer of its own: it imports only :mod:`dgz_cli.spec`.
"""
