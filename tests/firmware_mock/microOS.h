// cartctl's stand-in for the course's microOS scheduler, NOT the course's code.
//
// Written for cartctl from the API the bridge sketch uses (System.setHAL, setCommunicator,
// addThread, start, run), so that tests/test_firmware_avr.py can compile and link the sketch for
// the ATmega2560 without the course library. Only the names and types the sketch relies on follow
// the template; the bodies are minimal and cartctl's own: a fixed table of threads run by period
// on micros(), and a communicator with a simple framing of its own over Serial. Do not flash it.

#ifndef CARTCTL_MOCK_MICROOS_H
#define CARTCTL_MOCK_MICROOS_H

#include <Arduino.h>
#include <stdint.h>

// Thread priorities: when several threads are due, the highest runs first.
enum Priority { BELOWNORMAL = 1, NORMAL = 2, ABOVENORMAL = 3 };

// SEQUENTIAL staggers the first runs (1 ms apart, in the order added); SIMULTANEOUS makes them
// all due at once.
enum StartMode { SEQUENTIAL, SIMULTANEOUS };

// RESCHEDULED: a thread that fell more than a period behind skips the missed runs;
// CATCHUP: it runs them back to back.
enum RunMode { RESCHEDULED, CATCHUP };

// A thread function returns 0 when it is done for this period; anything else runs it again at
// the next pass. The type is the point of the mock: a void function must not compile here.
typedef int (*ThreadFunction)();

// The hardware layer the scheduler starts and the communicator reports buttons to.
class HAL {
  public:
    virtual bool init() = 0;
    virtual void control() = 0;
    virtual void button0callback() {}
    virtual void button1callback() {}

  protected:
    ~HAL() {}
};

// The serial link: receive() drains the port, transmit() sends the output channels,
// sendThreadInfo() a thread's timing (as the course's communicator interface has them).
class CommunicatorInterface {
  public:
    virtual void receive() = 0;
    virtual void transmit() = 0;
    virtual void sendThreadInfo(uint8_t id, uint8_t priority, uint32_t duration, uint32_t latency,
                                uint32_t total_duration, uint32_t total_latency,
                                uint32_t executions) = 0;

  protected:
    ~CommunicatorInterface() {}
};

#define MICROOS_FLOATS 8
#define MICROOS_INTS 4

// Frames of this mock, both ways: 0xA5, a type byte, the payload, the payload's byte sum.
//   'G' GPIO: 8 floats then 4 int16, little-endian (40 bytes)
//   'B' button: 1 byte, the button's number (host to cart)
//   'M' message: 1 length byte then the text (cart to host)
class SerialCommunicator : public CommunicatorInterface {
  public:
    SerialCommunicator();
    void begin(unsigned long baud);
    virtual void receive();
    virtual void transmit();
    virtual void sendThreadInfo(uint8_t id, uint8_t priority, uint32_t duration, uint32_t latency,
                                uint32_t total_duration, uint32_t total_latency,
                                uint32_t executions);
    void sendMessage(const String& text);

    float inFloat(uint8_t channel) const;
    int16_t inInt(uint8_t channel) const;
    void setOutFloat(uint8_t channel, float value);
    void setOutInt(uint8_t channel, int16_t value);

  private:
    enum State { WAIT_START, WAIT_TYPE, PAYLOAD, CHECKSUM };
    enum { START = 0xA5, GPIO_BYTES = MICROOS_FLOATS * 4 + MICROOS_INTS * 2 };

    void feed(uint8_t byte);
    void decode();
    void writeFrame(uint8_t type, const uint8_t* payload, uint8_t length);

    State _state;
    uint8_t _type;
    uint8_t _expected;
    uint8_t _length;
    uint8_t _sum;
    uint8_t _payload[GPIO_BYTES];
    float _in_floats[MICROOS_FLOATS];
    int16_t _in_ints[MICROOS_INTS];
    float _out_floats[MICROOS_FLOATS];
    int16_t _out_ints[MICROOS_INTS];
};

#define MICROOS_MAX_THREADS 6
#define MICROOS_FAST_DISABLE (1 << 3)  // configure(): no communication thread of the system's own

class MicroOS {
  public:
    MicroOS();
    void setHAL(HAL* hal);
    void setCommunicator(CommunicatorInterface* communicator);
    void configure(uint8_t config);  // MICROOS_FAST_DISABLE: the sketch receives and sends itself
    HAL* hal() const;
    CommunicatorInterface* communicator() const;

    // period_us: microseconds between two runs; start: run at once rather than from start().
    // Returns the thread's number, or -1 when the table is full.
    int8_t addThread(Priority priority, uint32_t period_us, int (*fcn)(), bool start);
    void startThread(int8_t id);
    void stopThread(int8_t id);

    void start(StartMode mode);  // hal->init(), the system's own threads, then the clock
    void run(RunMode mode);      // one pass: the most urgent due thread, if any

  private:
    struct Thread {
      ThreadFunction fcn;
      uint32_t period_us;
      uint32_t due_us;
      uint8_t priority;
      bool running;
    };

    Thread _threads[MICROOS_MAX_THREADS];
    uint8_t _count;
    uint8_t _config;
    HAL* _hal;
    CommunicatorInterface* _communicator;
};

extern MicroOS System;

#endif  // CARTCTL_MOCK_MICROOS_H
