// cartctl bridge sketch for the MECOtron cart (Arduino Mega 2560, microOS, the course template).
// Start-up as in the course template: the robot is microOS's hardware layer and communicator,
// and one 10 ms thread runs io() then control(). microOS adds its own threads for the serial link
// (receive, then one GPIO out per 10 ms) and the heartbeat. The bridge adds a 1 ms thread that
// drains the serial port, and drains it once more right before control(): microOS's own receive,
// once per 10 ms, lets the Mega's 63-byte receive ring overflow whenever two of the PC's 60-byte
// frames arrive between two of its drains. See firmware/README.md and docs/serial-protocol.md.

#include "robot.h"

static Robot robot;

// microOS threads return int (0: done for this period).
int update() {
  robot.io();       // apply the voltage stored at the previous tick, read the encoders
  robot.receive();  // the freshest command: one that has arrived by now acts at this tick
  robot.control();  // the bridge: held PC channels in, voltages and measurements out
  return 0;
}

int drainSerial() {
  robot.receive();  // the 63-byte receive ring never fills between two drains
  return 0;
}

void setup() {
  System.setHAL(&robot);  // System.start() calls robot.init()
  System.setCommunicator(robot.getCommunicator());
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
