"""Occtool's own files and outputs, apart from the range logs it reads (:mod:`occtool.io`).

``model``
    a fitted model's JSON file (:func:`~occtool.formats.model.save_model`, ``load_model``) and model sets.
``occmap``
    the world map of a run, ``world.occmap``.
``geojson``
    navigation polygons, obstacle and exploration points.
``nav2``
    Nav2 ``map_server`` maps (``map.yaml`` with ``map.pgm`` or ``map.png``).
``foxglove``
    the map of a run as MCAP for Foxglove.
``query_csv``
    answers of ``occtool query``.
``wgs84``
    GeoJSON in longitude/latitude (pyproj).
"""
