"""Vehicles on the map: drives of an ego and cooperative vehicles along routes (``drive``),
the generic lane sensor (``sensor``), its seeded error models (``sensor_errors``) and the
detection message each vehicle sends (``detection``)."""
