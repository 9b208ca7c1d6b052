// cartctl's stand-in for the course template's hardware layer, NOT the course's code
// (see mecotron.h). Pin numbers and scales are made up.

#include "mecotron.h"

static const uint8_t PWM_PIN[2] = {9, 10};        // H-bridge enable (PWM), motor A, B
static const uint8_t DIRECTION_PIN[2] = {7, 8};   // H-bridge direction
static const uint8_t ENCODER_PIN[2] = {2, 3};     // encoder channel A (external interrupt)
static const uint8_t QUADRATURE_PIN[2] = {4, 5};  // encoder channel B
static const uint8_t LED_PIN[2] = {22, 23};
static const float RAD_PER_COUNT[2] = {-0.0130900f, 0.0130900f};  // motor A's sign flip here

static volatile int32_t encoder_count[2] = {0, 0};

static void encoderEdgeA() {
  encoder_count[0] += digitalRead(ENCODER_PIN[0]) == digitalRead(QUADRATURE_PIN[0]) ? 1 : -1;
}

static void encoderEdgeB() {
  encoder_count[1] += digitalRead(ENCODER_PIN[1]) == digitalRead(QUADRATURE_PIN[1]) ? 1 : -1;
}

static int32_t readCount(uint8_t motor) {
  noInterrupts();
  const int32_t count = encoder_count[motor];
  interrupts();
  return count;
}

MECOtron::MECOtron() : _last_io_us(0) {
  for (uint8_t k = 0; k < 2; ++k) {
    _requested_v[k] = _applied_v[k] = _speed_rad_s[k] = _position_rad[k] = 0.0f;
    _last_count[k] = 0;
  }
}

bool MECOtron::init() {
  _communicator.begin(115200UL);
  for (uint8_t k = 0; k < 2; ++k) {
    pinMode(PWM_PIN[k], OUTPUT);
    pinMode(DIRECTION_PIN[k], OUTPUT);
    analogWrite(PWM_PIN[k], 0);
    pinMode(ENCODER_PIN[k], INPUT_PULLUP);
    pinMode(QUADRATURE_PIN[k], INPUT_PULLUP);
    pinMode(LED_PIN[k], OUTPUT);
    digitalWrite(LED_PIN[k], LOW);
    _requested_v[k] = _applied_v[k] = _speed_rad_s[k] = _position_rad[k] = 0.0f;
  }
  noInterrupts();
  encoder_count[0] = encoder_count[1] = 0;
  interrupts();
  _last_count[0] = _last_count[1] = 0;
  attachInterrupt(digitalPinToInterrupt(ENCODER_PIN[0]), encoderEdgeA, CHANGE);
  attachInterrupt(digitalPinToInterrupt(ENCODER_PIN[1]), encoderEdgeB, CHANGE);
  _last_io_us = micros();
  return true;
}

void MECOtron::control() {}

void MECOtron::button0callback() {}

void MECOtron::button1callback() {}

void MECOtron::applyVoltage(uint8_t motor) {
  const int16_t millivolts = (int16_t)(_requested_v[motor] * 1000.0f);  // as io() sends it
  const int32_t magnitude = millivolts < 0 ? -(int32_t)millivolts : millivolts;
  int32_t duty = magnitude * 255L / (int32_t)(BATTERY_VOLTAGE * 1000.0f);
  if (duty > 255) duty = 255;
  digitalWrite(DIRECTION_PIN[motor], millivolts < 0 ? HIGH : LOW);
  analogWrite(PWM_PIN[motor], (int)duty);
  _applied_v[motor] = (float)millivolts / 1000.0f;
}

void MECOtron::io() {
  const uint32_t now = micros();
  const float dt_s = (float)(now - _last_io_us) * 1e-6f;
  _last_io_us = now;
  for (uint8_t k = 0; k < 2; ++k) {
    applyVoltage(k);
    const int32_t count = readCount(k);
    _position_rad[k] = (float)count * RAD_PER_COUNT[k];
    _speed_rad_s[k] = dt_s > 0.0f ? (float)(count - _last_count[k]) * RAD_PER_COUNT[k] / dt_s : 0.0f;
    _last_count[k] = count;
  }
}

CommunicatorInterface* MECOtron::getCommunicator() { return &_communicator; }

float MECOtron::readFloat(uint8_t channel) { return _communicator.inFloat(channel); }

int16_t MECOtron::readInt(uint8_t channel) { return _communicator.inInt(channel); }

void MECOtron::writeFloat(uint8_t channel, float value) {
  _communicator.setOutFloat(channel, value);
}

void MECOtron::writeInt(uint8_t channel, int16_t value) { _communicator.setOutInt(channel, value); }

void MECOtron::setVoltageMotorA(float volts) { _requested_v[0] = volts; }

void MECOtron::setVoltageMotorB(float volts) { _requested_v[1] = volts; }

float MECOtron::getVoltageMotorA() { return _applied_v[0]; }

float MECOtron::getVoltageMotorB() { return _applied_v[1]; }

float MECOtron::getSpeedMotorA() { return _speed_rad_s[0]; }

float MECOtron::getSpeedMotorB() { return _speed_rad_s[1]; }

float MECOtron::getPositionMotorA() { return _position_rad[0]; }

float MECOtron::getPositionMotorB() { return _position_rad[1]; }

void MECOtron::message(String text) { _communicator.sendMessage(text); }

void MECOtron::LED1(bool on) { digitalWrite(LED_PIN[0], on ? HIGH : LOW); }

void MECOtron::LED2(bool on) { digitalWrite(LED_PIN[1], on ? HIGH : LOW); }
