"""The windseek MAVLink 2 dialect: ``common.xml`` plus ESC_INFO (290) and ESC_STATUS (291).

``windseek.xml`` is the source; ``windseek.py`` is generated from it by pymavlink's mavgen
(``python -m wire.dialect.generate``) and committed, so no code generation happens at
import or install time. ``common.xml``, ``standard.xml`` and ``minimal.xml`` are the copies
bundled with pymavlink 2.4.50 that the generated module was built from.
"""

from wire.dialect import windseek as mavlink

__all__ = ["mavlink"]
