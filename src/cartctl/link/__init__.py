"""The cart's serial link and its emulation.

The framing, without I/O (microOS MAVLink and the bridge channel map):

- :mod:`~cartctl.link.dialect`: message ids, CRC_EXTRA and the :class:`Encoder` of generation-A
  frames (plus :func:`encode_gpiox_v2` for generation B), on top of the pymavlink-generated module
  :mod:`~cartctl.link.vendor.microos_mavlink` that the package ships;
- :mod:`~cartctl.link.messages`: the decoded messages;
- :mod:`~cartctl.link.framer`: :class:`Framer`, bytes in, messages out, with :class:`LinkStats`;
- :mod:`~cartctl.link.text`: :class:`LineAssembler`, PRINT fragments to lines;
- :mod:`~cartctl.link.bridge`: the GPIO channel map of the bridge sketch, both directions;
- :mod:`~cartctl.link.firmware_id`: which of cartctl's firmwares sent a frame, by its float 6;
- :mod:`~cartctl.link.loop_delay`: the loop delay read from the bridge's echoes.

The host's side of the port: :mod:`~cartctl.link.cart_link` (open, wait for the cart, read,
write), :mod:`~cartctl.link.serial_cart` (the PC-side loop's plant, one tick per cart frame) and
:mod:`~cartctl.link.cart_monitor` (``cartctl monitor``). The cart, emulated:
:mod:`~cartctl.link.bridge_firmware` and :mod:`~cartctl.link.onboard_firmware` (the sketches'
logic in Python), :mod:`~cartctl.link.cart_uart` (the cart's serial port),
:mod:`~cartctl.link.virtual_cart` (the physics simulator behind a pseudo-terminal),
:mod:`~cartctl.link.virtual_serial` (the ``virtual`` plant) and :mod:`~cartctl.link.cart_faults`.

The package re-exports the public names (``__all__``) of the five framing modules; the others
are imported from where they are.

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
