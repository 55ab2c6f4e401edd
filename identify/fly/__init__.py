"""Adapters that fly the identification manoeuvre: in windseek's world (``world``) or through MAVLink on a
PX4 (``px4``). The estimation (``identify.pipeline``) never imports them."""
