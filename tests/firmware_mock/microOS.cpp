// cartctl's stand-in for the course's microOS scheduler, NOT the course's code (see microOS.h).

#include "microOS.h"

#include <string.h>

MicroOS System;

// ---- the communicator ----------------------------------------------------------------------

SerialCommunicator::SerialCommunicator()
    : _state(WAIT_START), _type(0), _expected(0), _length(0), _sum(0) {
  memset(_payload, 0, sizeof(_payload));
  for (uint8_t k = 0; k < MICROOS_FLOATS; ++k) _in_floats[k] = _out_floats[k] = 0.0f;
  for (uint8_t k = 0; k < MICROOS_INTS; ++k) _in_ints[k] = _out_ints[k] = 0;
}

void SerialCommunicator::begin(unsigned long baud) { Serial.begin(baud); }

void SerialCommunicator::receive() {
  while (Serial.available() > 0) feed((uint8_t)Serial.read());
}

void SerialCommunicator::feed(uint8_t byte) {
  switch (_state) {
    case WAIT_START:
      if (byte == START) _state = WAIT_TYPE;
      break;
    case WAIT_TYPE:
      _type = byte;
      _expected = byte == 'G' ? (uint8_t)GPIO_BYTES : (uint8_t)(byte == 'B' ? 1 : 0);
      _length = 0;
      _sum = 0;
      _state = _expected > 0 ? PAYLOAD : WAIT_START;
      break;
    case PAYLOAD:
      _payload[_length++] = byte;
      _sum = (uint8_t)(_sum + byte);
      if (_length == _expected) _state = CHECKSUM;
      break;
    case CHECKSUM:
      if (byte == _sum) decode();
      _state = WAIT_START;
      break;
  }
}

void SerialCommunicator::decode() {
  if (_type == 'G') {  // every input channel overwritten, as the sketch expects
    memcpy(_in_floats, _payload, sizeof(_in_floats));
    memcpy(_in_ints, _payload + sizeof(_in_floats), sizeof(_in_ints));
  } else if (_type == 'B' && System.hal() != 0) {
    if (_payload[0] == 0) System.hal()->button0callback();
    if (_payload[0] == 1) System.hal()->button1callback();
  }
}

void SerialCommunicator::writeFrame(uint8_t type, const uint8_t* payload, uint8_t length) {
  uint8_t sum = 0;
  for (uint8_t k = 0; k < length; ++k) sum = (uint8_t)(sum + payload[k]);
  Serial.write((uint8_t)START);
  Serial.write(type);
  Serial.write(payload, length);
  Serial.write(sum);
}

void SerialCommunicator::sendThreadInfo(uint8_t id, uint8_t priority, uint32_t duration,
                                        uint32_t latency, uint32_t total_duration,
                                        uint32_t total_latency, uint32_t executions) {
  // 'T': id, priority, then five uint32 (22 bytes): the mock's own frame, as long as microOS's
  uint8_t payload[22];
  const uint32_t words[5] = {duration, latency, total_duration, total_latency, executions};
  payload[0] = id;
  payload[1] = priority;
  for (uint8_t k = 0; k < 5; ++k) {
    for (uint8_t b = 0; b < 4; ++b) payload[2 + 4 * k + b] = (uint8_t)(words[k] >> (8 * b));
  }
  writeFrame('T', payload, sizeof(payload));
}

void SerialCommunicator::transmit() {
  uint8_t frame[GPIO_BYTES];
  memcpy(frame, _out_floats, sizeof(_out_floats));
  memcpy(frame + sizeof(_out_floats), _out_ints, sizeof(_out_ints));
  writeFrame('G', frame, GPIO_BYTES);
}

void SerialCommunicator::sendMessage(const String& text) {
  uint8_t frame[64];
  uint8_t length = text.length() < sizeof(frame) - 1 ? (uint8_t)text.length() : sizeof(frame) - 1;
  frame[0] = length;
  memcpy(frame + 1, text.c_str(), length);
  writeFrame('M', frame, (uint8_t)(length + 1));
}

float SerialCommunicator::inFloat(uint8_t channel) const {
  return channel < MICROOS_FLOATS ? _in_floats[channel] : 0.0f;
}

int16_t SerialCommunicator::inInt(uint8_t channel) const {
  return channel < MICROOS_INTS ? _in_ints[channel] : 0;
}

void SerialCommunicator::setOutFloat(uint8_t channel, float value) {
  if (channel < MICROOS_FLOATS) _out_floats[channel] = value;
}

void SerialCommunicator::setOutInt(uint8_t channel, int16_t value) {
  if (channel < MICROOS_INTS) _out_ints[channel] = value;
}

// ---- the scheduler -------------------------------------------------------------------------

static int communicationThread() {  // the serial link: drain, then one GPIO frame out
  CommunicatorInterface* communicator = System.communicator();
  if (communicator != 0) {
    communicator->receive();
    communicator->transmit();
  }
  return 0;
}

static int heartbeatThread() {  // the board's LED blinks while the scheduler runs
  digitalWrite(LED_BUILTIN, digitalRead(LED_BUILTIN) == HIGH ? LOW : HIGH);
  return 0;
}

MicroOS::MicroOS() : _count(0), _config(0), _hal(0), _communicator(0) {}

void MicroOS::configure(uint8_t config) { _config = config; }

void MicroOS::setHAL(HAL* hal) { _hal = hal; }

void MicroOS::setCommunicator(CommunicatorInterface* communicator) {
  _communicator = communicator;
}

HAL* MicroOS::hal() const { return _hal; }

CommunicatorInterface* MicroOS::communicator() const { return _communicator; }

int8_t MicroOS::addThread(Priority priority, uint32_t period_us, int (*fcn)(), bool start) {
  if (_count >= MICROOS_MAX_THREADS || fcn == 0) return -1;
  Thread& thread = _threads[_count];
  thread.fcn = fcn;
  thread.period_us = period_us;
  thread.due_us = micros();
  thread.priority = (uint8_t)priority;
  thread.running = start;
  return (int8_t)_count++;
}

void MicroOS::startThread(int8_t id) {
  if (id >= 0 && id < _count) {
    _threads[id].running = true;
    _threads[id].due_us = micros();
  }
}

void MicroOS::stopThread(int8_t id) {
  if (id >= 0 && id < _count) _threads[id].running = false;
}

void MicroOS::start(StartMode mode) {
  if (_hal != 0) _hal->init();
  pinMode(LED_BUILTIN, OUTPUT);
  if ((_config & MICROOS_FAST_DISABLE) == 0) addThread(NORMAL, 10000UL, &communicationThread, false);
  addThread(BELOWNORMAL, 500000UL, &heartbeatThread, false);
  const uint32_t now = micros();
  for (uint8_t k = 0; k < _count; ++k) {
    _threads[k].running = true;
    _threads[k].due_us = mode == SEQUENTIAL ? now + 1000UL * k : now;
  }
}

void MicroOS::run(RunMode mode) {
  const uint32_t now = micros();
  int8_t next = -1;
  for (uint8_t k = 0; k < _count; ++k) {
    const Thread& thread = _threads[k];
    if (!thread.running || (int32_t)(now - thread.due_us) < 0) continue;
    if (next < 0 || thread.priority > _threads[next].priority) next = (int8_t)k;
  }
  if (next < 0) return;
  Thread& thread = _threads[next];
  if (thread.fcn() != 0) return;  // not done: due again at the next pass
  thread.due_us += thread.period_us;
  if (mode == RESCHEDULED && (int32_t)(now - thread.due_us) >= 0) {
    thread.due_us = now + thread.period_us;  // fell a period behind: skip the missed runs
  }
}
