"""Byte encodings of servo controllers' serial protocols.

A protocol turns "set channel *c* to *t* quarter-microseconds" into the bytes a
controller understands. It knows nothing of ports, timing or plans, so that a
second controller (say, a plain PWM board on a serial line) only needs a new
:class:`ServoProtocol` subclass and an entry in :data:`PROTOCOLS`.

Implemented:

``maestro``
    The Pololu Maestro's *compact protocol*: Set Target is
    ``0x84, channel, target & 0x7F, (target >> 7) & 0x7F`` with the target in
    quarter-microseconds (14 bits, 0…16383). Set Speed (``0x87``) and Set
    Acceleration (``0x89``) have the same layout; Get Position is
    ``0x90, channel`` and the Maestro answers with two 8-bit bytes, low first.
``maestro-pololu``
    The same commands in the Maestro's *Pololu protocol*, for a Maestro
    sharing a serial line with other Pololu devices:
    ``0xAA, device number, command & 0x7F, data…`` (device number 12 by default).

On a Maestro channel configured as a digital *output*, a target below 6000
(1500 µs) drives the line low and 6000 or more drives it high; that is how
the LED is switched.
"""

from __future__ import annotations

from abc import ABC, abstractmethod

from ..errors import ServoscopeError

__all__ = [
    "ServoProtocol",
    "MaestroCompact",
    "MaestroPololu",
    "PROTOCOLS",
    "get_protocol",
    "QUARTER_US_PER_US",
    "MAESTRO_MAX_TARGET_QUS",
    "MAESTRO_OUTPUT_HIGH_QUS",
    "MAESTRO_OUTPUT_LOW_QUS",
]

#: Quarter-microseconds per microsecond: the Maestro's target unit.
QUARTER_US_PER_US = 4
#: Largest target a 14-bit Maestro field can carry, quarter-µs.
MAESTRO_MAX_TARGET_QUS = 0x3FFF
#: Target that drives a digital-output channel high (2000 µs; ≥ 6000 is high).
#: 2000 µs rather than the 1500 µs threshold so that rounding can never land on it.
MAESTRO_OUTPUT_HIGH_QUS = 8000
#: Target that drives a digital-output channel low. 0 also means "no pulses"
#: on a channel left configured as a servo, so the LED is dark either way.
MAESTRO_OUTPUT_LOW_QUS = 0


class ServoProtocol(ABC):
    """What the driver needs from a controller's serial protocol.

    Subclasses encode commands as bytes; they do no I/O.

    Attributes
    ----------
    name : str
        The name used by ``servoscope drive --protocol``.
    max_channel : int
        Highest channel number the protocol can address.
    max_target_qus : int
        Largest encodable target, quarter-µs.
    """

    name: str = ""
    max_channel: int = 23
    max_target_qus: int = MAESTRO_MAX_TARGET_QUS

    def check_channel(self, channel: int, what: str = "channel") -> None:
        """Refuse a channel the protocol cannot address (ServoscopeError)."""
        if not isinstance(channel, int) or isinstance(channel, bool) or not 0 <= channel <= self.max_channel:
            raise ServoscopeError(f"--{what} {channel!r}: {self.name} channels are 0…{self.max_channel}")

    def _check_target(self, target_qus: int) -> None:
        if not 0 <= target_qus <= self.max_target_qus:
            raise ServoscopeError(
                f"target {target_qus} quarter-µs is outside 0…{self.max_target_qus} for {self.name}"
            )

    @abstractmethod
    def set_target(self, channel: int, target_qus: int) -> bytes:
        """Bytes that set ``channel``'s target.

        Parameters
        ----------
        channel : int
            Controller channel.
        target_qus : int
            Pulse width in quarter-microseconds (servo channel), or a level
            (output channel: see :meth:`output_level_qus`).
        """

    def output_level_qus(self, high: bool) -> int:
        """Target (quarter-µs) that drives a digital-output channel high or low."""
        return MAESTRO_OUTPUT_HIGH_QUS if high else MAESTRO_OUTPUT_LOW_QUS

    def setup(self, channel: int) -> bytes:
        """Bytes sent once before driving ``channel`` (may be empty)."""
        return b""


def _split14(value: int) -> tuple[int, int]:
    """A 14-bit value as two 7-bit data bytes, low first (the MSB of data bytes is 0)."""
    return value & 0x7F, (value >> 7) & 0x7F


class MaestroCompact(ServoProtocol):
    """Pololu Maestro, compact protocol (the Maestro alone on its serial line)."""

    name = "maestro"
    SET_TARGET = 0x84
    SET_SPEED = 0x87
    SET_ACCELERATION = 0x89
    GET_POSITION = 0x90

    def _command(self, command: int, data: bytes) -> bytes:
        return bytes([command]) + data

    def _channel_value(self, command: int, channel: int, value: int) -> bytes:
        self.check_channel(channel)
        self._check_target(value)
        low, high = _split14(value)
        return self._command(command, bytes([channel, low, high]))

    def set_target(self, channel: int, target_qus: int) -> bytes:
        """Set Target: ``0x84, channel, low 7 bits, high 7 bits`` (target in quarter-µs)."""
        return self._channel_value(self.SET_TARGET, channel, int(target_qus))

    def set_speed(self, channel: int, speed: int) -> bytes:
        """Set Speed (units of 0.25 µs / 10 ms; 0 = unlimited)."""
        return self._channel_value(self.SET_SPEED, channel, int(speed))

    def set_acceleration(self, channel: int, acceleration: int) -> bytes:
        """Set Acceleration (units of 0.25 µs / 10 ms / 80 ms; 0 = unlimited)."""
        return self._channel_value(self.SET_ACCELERATION, channel, int(acceleration))

    def get_position(self, channel: int) -> bytes:
        """Get Position request; the Maestro answers two bytes, see :meth:`parse_position`."""
        self.check_channel(channel)
        return self._command(self.GET_POSITION, bytes([channel]))

    @staticmethod
    def parse_position(reply: bytes) -> int:
        """The Get Position reply (8-bit low byte, 8-bit high byte) as quarter-µs."""
        if len(reply) != 2:
            raise ServoscopeError(f"Get Position: expected a 2-byte reply, got {len(reply)} bytes")
        return reply[0] | (reply[1] << 8)

    def setup(self, channel: int) -> bytes:
        """Speed and acceleration limits off, so the Maestro does not low-pass the sine."""
        # A speed or acceleration limit configured in the Maestro Control Center
        # would filter the command and bias the measured gain and phase.
        return self.set_speed(channel, 0) + self.set_acceleration(channel, 0)


class MaestroPololu(MaestroCompact):
    """Pololu Maestro, Pololu protocol: ``0xAA, device number, command & 0x7F, data…``.

    Parameters
    ----------
    device_number : int
        The Maestro's device number (0…127; 12 out of the box).
    """

    name = "maestro-pololu"

    def __init__(self, device_number: int = 12) -> None:
        if not 0 <= int(device_number) <= 0x7F:
            raise ServoscopeError(f"--device-number {device_number}: must be 0…127")
        self.device_number = int(device_number)

    def _command(self, command: int, data: bytes) -> bytes:
        # The compact command byte becomes a data byte: its MSB is cleared.
        return bytes([0xAA, self.device_number, command & 0x7F]) + data


#: Protocols by ``--protocol`` name.
PROTOCOLS: dict[str, type[ServoProtocol]] = {
    MaestroCompact.name: MaestroCompact,
    MaestroPololu.name: MaestroPololu,
}


def get_protocol(name: str, **options) -> ServoProtocol:
    """A protocol by name.

    Parameters
    ----------
    name : str
        A key of :data:`PROTOCOLS`.
    **options
        Passed to the protocol's constructor (``device_number`` for
        ``maestro-pololu``); options a protocol does not take are ignored.

    Raises
    ------
    ServoscopeError
        For an unknown name.
    """
    cls = PROTOCOLS.get(name)
    if cls is None:
        raise ServoscopeError(f"--protocol {name!r}: unknown (known: {', '.join(sorted(PROTOCOLS))})")
    if cls is MaestroPololu:
        return cls(**{k: v for k, v in options.items() if k == "device_number"})
    return cls()
