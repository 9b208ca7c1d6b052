// cartctl bridge sketch (version 2) for the MECOtron cart (Arduino Mega 2560, microOS, the course
// template). The robot is microOS's hardware layer and communicator, as in the template. The
// bridge runs its own tick instead of microOS's communication thread, so that the PC's command
// for a measurement acts at the next io(), one tick later, as on-board control does:
//
//   every 10 ms: drain the serial port (the newest command becomes the next io()'s voltage),
//                io() (apply it, read the encoders), control() (measurements out), send one GPIO
//   every 1 ms:  drain the serial port (the newest command replaces the stored voltage)
//
// The line runs at 500 kbaud (BRIDGE_BAUD): a 60-byte frame takes 1.2 ms each way, so the cart's
// frame and the PC's reply both fit in the tick, with the Mega's USB bridge's latency counted.
// (1 Mbaud would be faster still, but the receive interrupt then has 20 us to take each byte,
// and the course's encoder interrupts, 152 cycles each, delay it past that: bytes are lost.)
// See firmware/README.md and docs/serial-protocol.md for the tick budget.

#include "robot.h"

// The Arduino core's receive ring must hold what the line carries while the 10 ms thread runs
// (50 bytes a ms at 500 kbaud, ~1.2 ms, and more when two replies come together): build with
// -DSERIAL_RX_BUFFER_SIZE=256 (firmware/README.md).
// Its transmit buffer must hold the 180 bytes sent per tick, so that io() and the drains never
// wait for the line: -DSERIAL_TX_BUFFER_SIZE=256.
#if !defined(SERIAL_RX_BUFFER_SIZE) || SERIAL_RX_BUFFER_SIZE < 256 || !defined(SERIAL_TX_BUFFER_SIZE) || SERIAL_TX_BUFFER_SIZE < 256
#error "build with -DSERIAL_RX_BUFFER_SIZE=256 -DSERIAL_TX_BUFFER_SIZE=256: at 500 kbaud the 64-byte rings are too small (see firmware/README.md)"
#endif

static Robot robot;
static BridgeTiming timing;  // what the THREAD_INFO frames after each GPIO report

static void drainAndWatch() {
  const uint16_t waiting = (uint16_t)Serial.available();  // the receive ring before this drain
  if (waiting > timing.ring_high_water_bytes) timing.ring_high_water_bytes = waiting;
  robot.receive();
}

// microOS threads return int (0: done for this period).
int update() {
  const uint32_t startUs = micros();
  timing.tick_interval_us = startUs - timing.last_start_us;
  timing.last_start_us = startUs;
  drainAndWatch();   // the freshest command: one that has arrived by now acts at this io()
  robot.io();        // apply the stored voltage, read the encoders
  robot.control();   // measurements and the echo out, the watchdog checked
  timing.tick_busy_us = micros() - startUs;
  robot.transmit(&timing);  // one GPIO, then the tick's timing (resets the maxima)
  return 0;
}

int drainSerial() {
  const uint32_t startUs = micros();
  drainAndWatch();  // a command that arrives mid-tick is stored for the next io() at once
  const uint32_t tookUs = micros() - startUs;
  if (tookUs > timing.longest_drain_us) timing.longest_drain_us = tookUs;
  return 0;
}

void setup() {
  System.setHAL(&robot);  // System.start() calls robot.init()
  System.setCommunicator(robot.getCommunicator());
  System.configure(MICROOS_FAST_DISABLE);  // the bridge receives and sends in its own tick
  System.addThread(ABOVENORMAL, 10000, &update, false);  // period in microseconds
  System.addThread(NORMAL, 1000, &drainSerial, false);
  System.start(SEQUENTIAL);
}

int main(void) {
  init();  // the Arduino core's timers and ADC
  setup();
  for (;;) {
    System.run(RESCHEDULED);
  }
  return 0;
}
