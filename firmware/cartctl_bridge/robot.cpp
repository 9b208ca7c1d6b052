// cartctl bridge sketch: the cart runs no controller of its own; it applies the voltages the PC
// sends and streams speeds, applied voltages and positions back at 100 Hz (firmware/README.md).
//
// Channel map (docs/serial-protocol.md):
//   PC -> cart  float 0, 1  requested voltage A, B (V)
//               int 0       host sequence number, 0..32767, +1 per frame
//               int 1       1 = drive, 0 = stop
//   cart -> PC  float 0, 1  speed A, B (rad/s)
//               float 2, 3  voltage A, B on the H-bridges at this tick (V)
//               float 4, 5  wheel position A, B (rad)
//               float 6     bridge version (2)
//               int 0       echo: the host sequence number of the command io() applied at this tick
//               int 1       tick counter, 0..32767
//               int 2       status: bit 0 driving, bit 1 watchdog tripped
//               int 3       host sequence numbers the cart never saw (lost frames), 0..32767
//
// Motor A: the template's getSpeedMotorA() and getPositionMotorA() already carry motor A's sign
// flip (a negative encoder scale in mecotron.h), so the bridge passes both motors through
// unchanged and a positive voltage is assumed to give a positive speed on both. If motor A runs
// backwards for a positive request on your cart, fix the sign in mecotron.h, not here.

#include "robot.h"

bool Robot::init() {
  MECOtron::init();            // serial, PWM timer, encoders, LEDs
  Serial.begin(BRIDGE_BAUD);   // the template opens 115200; the bridge runs the line at 500 kbaud
  bridge_reset(&_bridge);
  setVoltageMotorA(0.0f);
  setVoltageMotorB(0.0f);
  message("cartctl bridge ready");  // shows as a PRINT line in cartctl and QRC
  return true;
}

// The H-bridge saturates at the 12 V supply by itself, but io() converts the voltage to int16
// millivolts first, which overflows beyond 32.767 V: clamp here so any request is safe.
static float clampToSupply(float volts) {
  if (volts > BATTERY_VOLTAGE) return BATTERY_VOLTAGE;
  if (volts < -BATTERY_VOLTAGE) return -BATTERY_VOLTAGE;
  return volts;
}

// Drains the serial port through microOS's communicator (which overwrites the held input channels
// with every GPIO it decodes), hands the held channels to the bridge with the time, and stores the
// voltages the bridge decided for the next io(): the newest command acts there. Called every 1 ms
// from its own thread and at the start of each tick, right before io().
void Robot::receive() {
  getCommunicator()->receive();
  float in_floats[BRIDGE_FLOATS];
  int32_t in_ints[BRIDGE_INTS];
  for (uint8_t k = 0; k < BRIDGE_FLOATS; ++k) in_floats[k] = readFloat(k);
  for (uint8_t k = 0; k < BRIDGE_INTS; ++k) in_ints[k] = readInt(k);
  bridge_receive(&_bridge, in_floats, in_ints, (uint32_t)millis());
  setVoltageMotorA(clampToSupply(_bridge.command_a_v));  // written to the H-bridge by io()
  setVoltageMotorB(clampToSupply(_bridge.command_b_v));
}

void Robot::control() {
  BridgeIO io;
  io.speed_a_rad_s = getSpeedMotorA();
  io.speed_b_rad_s = getSpeedMotorB();
  io.applied_a_v = getVoltageMotorA();  // what io() put on the H-bridge at this tick
  io.applied_b_v = getVoltageMotorB();
  io.position_a_rad = getPositionMotorA();
  io.position_b_rad = getPositionMotorB();

  BridgeVoltages v = bridge_control(&_bridge, &io, (uint32_t)millis());
  setVoltageMotorA(clampToSupply(v.a_v));  // the next io(), unless a newer command comes first
  setVoltageMotorB(clampToSupply(v.b_v));

  for (uint8_t k = 0; k < BRIDGE_FLOATS; ++k) writeFloat(k, _bridge.out_floats[k]);
  for (uint8_t k = 0; k < BRIDGE_INTS; ++k) writeInt(k, (int16_t)_bridge.out_ints[k]);

  LED1(_bridge.driving ? ON : OFF);  // LED 1: the PC's voltages are applied
  LED2(_bridge.tripped ? ON : OFF);  // LED 2: watchdog tripped (no PC, or it stopped sending)
}

// The GPIO (60 bytes), then four THREAD_INFO frames (30 bytes each, ids 200..203): how long this
// tick's drain, io() and control() took, the longest 1 ms drain, the time since the previous tick
// started (all in us) and the most bytes a drain found waiting in the receive ring, since the
// previous tick. They are worth reading, and they make the cart send 120 bytes after its GPIO: the
// Mega's USB chip (an ATmega16U2) holds the cart's bytes until its 4.096 ms timer runs out or more
// than 96 are waiting, so the GPIO reaches the PC within 2 ms of its last byte instead of up to
// 4 ms (docs/serial-protocol.md). The transmit buffer is built 256 bytes long, so this does not
// wait for the line.
void Robot::transmit(BridgeTiming* timing) {
  getCommunicator()->transmit();  // microOS's GPIO out: the channels control() wrote
  _ticks += 1;
  const uint32_t values[BRIDGE_TIMING_REPORTS] = {timing->tick_busy_us, timing->longest_drain_us,
                                                  timing->tick_interval_us,
                                                  timing->ring_high_water_bytes};
  for (uint8_t k = 0; k < BRIDGE_TIMING_REPORTS; ++k) {
    getCommunicator()->sendThreadInfo(BRIDGE_TIMING_FIRST_ID + k, 0, values[k], 0, 0, 0, _ticks);
  }
  timing->longest_drain_us = 0;
  timing->ring_high_water_bytes = 0;
}

void Robot::button0callback() {
  message("bridge: the PC drives");  // no local enable: drive comes from int channel 1
}

void Robot::button1callback() {
  init();  // encoders to zero, bridge back to power-on state (tripped until a new frame)
  message("Reset.");
}
