// cartctl bridge sketch for the MECOtron cart (Arduino Mega 2560, microOS, the course template).
// Start-up as in the course template: the robot is microOS's hardware layer and communicator,
// and one 10 ms thread runs io() then control(). microOS adds its own threads for the serial link
// (receive, then one GPIO out per 10 ms) and the heartbeat. See firmware/README.md.

#include "robot.h"

static Robot robot;

void update() {
  robot.io();       // apply the voltage stored at the previous tick, read the encoders
  robot.control();  // the bridge: held PC channels in, voltages and measurements out
}

void setup() {
  System.setHAL(&robot);  // System.start() calls robot.init()
  System.setCommunicator(robot.getCommunicator());
  System.addThread(ABOVENORMAL, 10000, &update, false);  // period in microseconds
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
