"""The simulated world: what a real vehicle would experience.

Vehicle dynamics (``dynamics``: 6-DOF rigid body, RK4, ground contact) under the paper's rotor
model (:mod:`vehicle.rotor_model`), the wind (``wind``), the chemical plume (``plume``), and the
sensors (``sensors``: IMU, ESC, GNSS, barometer, magnetometer; ``chem_sensor``). The world takes
rotor commands and returns sensor samples and truth; it has no autopilot inside.
"""
