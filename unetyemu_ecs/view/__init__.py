"""The built-in 3D web view: the city, every vehicle, LiDAR points and camera images in a browser.

``unetyemu run WORLD --view [PORT]`` (``Simulation(world, view=PORT)``) serves a page on
``http://127.0.0.1:PORT/`` fed live from the simulation's snapshots (:mod:`.transport`);
``unetyemu view RECORDING`` serves the same page fed from a rosbag2 written by ``--record``, with
play, pause and seek (:mod:`.replay`). One port serves both the page's static files and its
WebSocket (:mod:`.server`); the wire protocol is in :mod:`.wire`, the scene in :mod:`.scene`, the
per-frame messages in :mod:`.frames`. The page is plain ES modules under ``static/``; three.js is
vendored there from npm at build time (``web/``), so nothing is fetched from the internet.
"""
