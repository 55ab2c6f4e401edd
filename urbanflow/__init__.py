"""The urban diagnostic wind field as a pure computation, below both the world and the mission.

A QUIC-URB-style mean wind among buildings (Roeckle / QUIC-URB parameterizations and a
variational mass-consistent adjustment): :mod:`.config` (validated scene), :mod:`.geometry`,
:mod:`.parameterizations`, :mod:`.initial_field`, :mod:`.solver`, :mod:`.solve`, :mod:`.field`,
:mod:`.sampling` (numba samplers). Plain synchronous code without I/O: the simulator's world
(:mod:`sitl.world.urban`: cache, scenario layouts, the world's wind model) and a mission's
source-term estimation (:mod:`mission.strategies.ste_urban`, from the buildings it knows and its
estimated wind) both build on it. Nothing is computed at import.

Conventions: SI units, NED (x north, y east, z down, ground z = 0; configuration heights are
positive metres above ground), wind = air-mass velocity in NED.
"""
