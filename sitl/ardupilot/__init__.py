"""windseek as ArduPilot SITL's physics (the JSON interface): see ``README.md`` in this folder."""
