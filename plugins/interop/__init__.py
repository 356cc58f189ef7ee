"""Interoperability with other tracking libraries (package ``workbench_interop``).

- :mod:`.stonesoup_filters`: Stone Soup's Kalman, extended, unscented, cubature and particle filters as workbench
  filters (``ss-kf``, ``ss-ekf``, ``ss-ukf``, ``ss-ckf``, ``ss-pf``), registered as the plugin
  ``stonesoup_interop``;
- :mod:`.stonesoup_export`: truths, detections and tracks as Stone Soup ``GroundTruthPath``, ``Detection`` /
  ``Clutter`` and ``Track`` objects;
- :mod:`.stonesoup_models`: the model conversions both use;
- :mod:`.stonesoup_available`: whether Stone Soup is installed, and the named error where it is needed.

Stone Soup is an optional extra: ``pip install "workbench[stonesoup]"``.  Without it the plugin registers no
filter, and the export functions raise an ``ImportError`` that says how to install it.
"""
