#ifndef ROBOT_H
#define ROBOT_H

// The cartctl bridge on the course template: the Robot class of the MECOtron template, whose
// control() passes the PC's voltages to the motors and streams the measurements back
// (firmware/README.md). mecotron.h, the template's hardware layer, is not shipped with cartctl:
// copy it from your course template (the folder of CT-Student.ino) into this folder.

#if defined(__has_include)
#if !__has_include("mecotron.h")
#error "mecotron.h is missing: copy it from the course template next to robot.h (see firmware/README.md)"
#endif
#endif

#include "mecotron.h"      // the template's MECOtron class: motors, encoders, GPIO helpers
#include "bridge_logic.h"  // the contract, plain C++ (tested on the PC against the virtual cart)

class Robot : public MECOtron {
  private:
    BridgeState _bridge;  // held channels, outputs, tick counter, watchdog
    uint32_t _ticks = 0;  // ticks since power-on

  public:
    Robot() { bridge_reset(&_bridge); }

    bool init();     // the template's set-up, then the bridge at power-on state
    void receive();   // drain the serial port, hand the held PC channels over, store the voltages
    void control();   // every 10 ms, after receive() and io()
    // One GPIO with what control() wrote, then four THREAD_INFO frames with the tick's timing.
    void transmit(BridgeTiming* timing);

    void button0callback();  // QRC button 0: says that the PC drives (no local enable)
    void button1callback();  // QRC button 1: reset, as in the template
};

#endif  // ROBOT_H
