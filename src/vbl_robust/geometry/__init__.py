"""Camera model, runway frame, LARD attitude conventions and geodesy.

Modules: :mod:`.camera` (intrinsics, LARD attitude, projection; the conventions), :mod:`.geodesy` (geodetic ↔
runway frame, the runway database).
"""
