"""The cart's serial link, without I/O: microOS MAVLink framing and the bridge channel map.

- :mod:`~cartctl.link.dialect`: message ids, CRC_EXTRA and the :class:`Encoder` of generation-A
  frames (plus :func:`encode_gpiox_v2` for generation B), on top of the pymavlink-generated module
  :mod:`~cartctl.link.vendor.microos_mavlink` that the package ships;
- :mod:`~cartctl.link.messages`: the decoded messages;
- :mod:`~cartctl.link.framer`: :class:`Framer`, bytes in, messages out, with :class:`LinkStats`;
- :mod:`~cartctl.link.text`: :class:`LineAssembler`, PRINT fragments to lines;
- :mod:`~cartctl.link.bridge`: the GPIO channel map of the bridge sketch, both directions.

The package re-exports the public names (``__all__``) of these five modules.
:mod:`~cartctl.link.firmware_id` (which of cartctl's firmwares sent a frame, by its float 6, and
the names of its channels) is imported from where it is.

See docs/serial-protocol.md for the wire protocol.
"""

from cartctl.link import bridge, dialect, framer, messages, text
from cartctl.link.bridge import *  # noqa: F403
from cartctl.link.dialect import *  # noqa: F403
from cartctl.link.framer import *  # noqa: F403
from cartctl.link.messages import *  # noqa: F403
from cartctl.link.text import *  # noqa: F403

__all__ = []
__all__ += bridge.__all__
__all__ += dialect.__all__
__all__ += framer.__all__
__all__ += messages.__all__
__all__ += text.__all__
