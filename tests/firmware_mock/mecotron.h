// cartctl's stand-in for the course template's mecotron.h, NOT the course's code.
//
// Written for cartctl from the helpers the bridge sketch calls, so that tests/test_firmware_avr.py
// can compile and link firmware/cartctl_bridge for the ATmega2560 without the course library (the
// sketch's users copy the real mecotron.h in). The names and types follow the template as the
// sketch uses them; the bodies are cartctl's own and only plausible: PWM and direction pins for
// the H-bridges, encoder interrupts, GPIO channels held by the mock microOS communicator. The pin
// numbers and scales are made up. Do not flash it.

#ifndef MECOTRON_H
#define MECOTRON_H

#include <Arduino.h>
#include <stdint.h>

#include "microOS.h"

#define BATTERY_VOLTAGE 12.0f  // the H-bridges' supply (V)
#define ON true
#define OFF false

class MECOtron : public HAL {
  public:
    MECOtron();

    virtual bool init();  // serial link, PWM and direction pins, encoders, LEDs
    virtual void control();
    virtual void button0callback();
    virtual void button1callback();

    void io();  // apply the stored voltages, read the encoders
    CommunicatorInterface* getCommunicator();

    // GPIO channels of the serial link.
    float readFloat(uint8_t channel);
    int16_t readInt(uint8_t channel);
    void writeFloat(uint8_t channel, float value);
    void writeInt(uint8_t channel, int16_t value);

    // Motors: the voltage set here reaches the H-bridge at the next io().
    void setVoltageMotorA(float volts);
    void setVoltageMotorB(float volts);
    float getVoltageMotorA();  // on the H-bridge since the last io(), quantised to 1 mV
    float getVoltageMotorB();
    float getSpeedMotorA();  // rad/s over the last io() period
    float getSpeedMotorB();
    float getPositionMotorA();  // rad since init()
    float getPositionMotorB();

    void message(String text);
    void LED1(bool on);
    void LED2(bool on);

  private:
    void applyVoltage(uint8_t motor);

    SerialCommunicator _communicator;
    float _requested_v[2];
    float _applied_v[2];
    float _speed_rad_s[2];
    float _position_rad[2];
    int32_t _last_count[2];
    uint32_t _last_io_us;
};

#endif  // MECOTRON_H
