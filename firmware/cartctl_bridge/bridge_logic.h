// cartctl bridge: the contract logic of the bridge sketch, as plain C++ with no Arduino dependency.
//
// The contract is docs/serial-protocol.md (the channel map is also in firmware/README.md). Its
// Python twin is src/cartctl/link/bridge_firmware.py (class BridgeFirmware), which the virtual
// cart runs; tests/test_firmware.py compiles this file with g++ and compares both, tick by tick.
// Change one, change the other.
//
// Bridge version 2. Its 10 ms thread runs, in this order: a drain of the serial port, io(),
// control(), then one GPIO out; a 1 ms thread drains as well. The sketch calls bridge_receive()
// after every drain, with the channels microOS holds from the host's last GPIO and the time in
// ms: it decides at once what the next io() applies (bridge_command), so the host's newest
// command acts at the next io() (one tick after the measurement it answers, as on-board control).
// bridge_control() runs once per control(), after io().
//
// Rules: the requested voltages (float 0 and 1) pass while drive (int 1) is 1 and the host's
// sequence number (int 0) keeps changing; a request that is not a finite number counts as 0 V.
// When no new sequence number has arrived for BRIDGE_WATCHDOG_MS, the watchdog trips (checked at
// every drain and at control()): 0 V until a new one arrives. The zero reaches the motor at the
// next io(), so the motors stop at most BRIDGE_WATCHDOG_MS + 1 tick (+ the drain period) after the
// host's last frame arrived. It starts tripped, so nothing moves before the host's first frame.
// Sequence numbers the host skipped are counted (frames lost on the way) and sent back. The echo
// (int 0) is the sequence number of the command io() applied at this tick.

#ifndef CARTCTL_BRIDGE_LOGIC_H
#define CARTCTL_BRIDGE_LOGIC_H

#include <stdint.h>

#define BRIDGE_FLOATS 8            // GPIO float channels, each way
#define BRIDGE_INTS 4              // GPIO int channels, each way
#define BRIDGE_TICK_MODULO 32768L  // tick counter and sequence numbers wrap here (int16 helpers)
#define BRIDGE_WATCHDOG_MS 70UL   // no new sequence number for this long at control(): trip
#define BRIDGE_SEQ_WINDOW 256L     // a jump beyond this (or backwards) is a new host, not a loss
#define BRIDGE_STATUS_DRIVING 1    // status bit 0: the requested voltages are applied
#define BRIDGE_STATUS_WATCHDOG 2   // status bit 1: the watchdog has tripped
#define BRIDGE_VERSION 2           // sent in float channel 6; bridges before version 2 send 0
#define BRIDGE_VERSION_CHANNEL 6
#define BRIDGE_TIMING_FIRST_ID 200 // THREAD_INFO ids 200..203 after each GPIO (BridgeTiming)
#define BRIDGE_TIMING_REPORTS 4
#define BRIDGE_BAUD 500000UL       // the line: 500 kbaud 8N1, exact on a 16 MHz AVR (1.2 ms a frame)

// What io() read at this tick and what it wrote to the H-bridges.
struct BridgeIO {
  float speed_a_rad_s;
  float speed_b_rad_s;
  float applied_a_v;  // on the H-bridge at this tick (set at the previous one), quantised
  float applied_b_v;
  float position_a_rad;
  float position_b_rad;
};

// What the sketch reports after each GPIO, one THREAD_INFO each (the value in its duration field):
// 200 the 10 ms thread's drain + io() + control() (us), 201 the longest 1 ms drain since the
// previous tick (us), 202 the time since the previous tick started (us), 203 the most bytes a drain
// found waiting in the receive ring since the previous tick.
struct BridgeTiming {
  uint32_t tick_busy_us;
  uint32_t longest_drain_us;
  uint32_t tick_interval_us;
  uint32_t ring_high_water_bytes;
  uint32_t last_start_us;
};

// The voltages control() stores for the next tick's io().
struct BridgeVoltages {
  float a_v;
  float b_v;
};

// The held input channels, the output channels and the watchdog.
struct BridgeState {
  float in_floats[BRIDGE_FLOATS];
  int32_t in_ints[BRIDGE_INTS];
  float out_floats[BRIDGE_FLOATS];
  int32_t out_ints[BRIDGE_INTS];
  int32_t tick;            // 0 .. BRIDGE_TICK_MODULO - 1, +1 per control()
  int32_t last_seq;        // the last new host sequence number seen
  uint32_t last_new_ms;    // when it was seen (the caller's ms clock)
  int32_t frames_lost;     // host sequence numbers skipped, 0 .. BRIDGE_TICK_MODULO - 1
  bool seen;               // a host frame has arrived since reset
  bool driving;            // as decided at the last drain or control()
  bool tripped;
  float command_a_v;       // what the next io() applies (V)
  float command_b_v;
  int32_t command_seq;     // the host sequence number that command came with
};

// A NaN or an infinity is not equal to itself minus itself; avoids depending on <math.h>'s
// isfinite, which differs between avr-libc and a desktop C++ library.
static inline bool bridge_is_finite(float value) {
  float zero = value - value;
  return zero == zero;
}

// Power-on state: every channel 0, the watchdog tripped until the host's first frame.
static inline void bridge_reset(BridgeState* s) {
  for (int k = 0; k < BRIDGE_FLOATS; ++k) {
    s->in_floats[k] = 0.0f;
    s->out_floats[k] = 0.0f;
  }
  for (int k = 0; k < BRIDGE_INTS; ++k) {
    s->in_ints[k] = 0;
    s->out_ints[k] = 0;
  }
  s->tick = 0;
  s->last_seq = 0;
  s->last_new_ms = 0;
  s->frames_lost = 0;
  s->seen = false;
  s->driving = false;
  s->tripped = true;
  s->command_a_v = 0.0f;
  s->command_b_v = 0.0f;
  s->command_seq = 0;
}

// What the next io() applies, decided from the held channels and the watchdog at now_ms.
static inline void bridge_command(BridgeState* s, uint32_t now_ms) {
  s->tripped = !s->seen || (uint32_t)(now_ms - s->last_new_ms) >= BRIDGE_WATCHDOG_MS;
  s->driving = s->in_ints[1] == 1 && !s->tripped;
  s->command_a_v = (s->driving && bridge_is_finite(s->in_floats[0])) ? s->in_floats[0] : 0.0f;
  s->command_b_v = (s->driving && bridge_is_finite(s->in_floats[1])) ? s->in_floats[1] : 0.0f;
  s->command_seq = s->in_ints[0];
}

// After a drain of the serial port: the channels microOS holds from the host's last GPIO (every
// input channel overwritten), seen at now_ms. A sequence number that differs from the last one is a
// new frame: it feeds the watchdog, and the numbers between the two were lost on the way (a jump
// backwards or beyond BRIDGE_SEQ_WINDOW is a new host process, not a loss). At power-on the held
// channels are 0, so a first host frame counts once its sequence number is not 0.
static inline void bridge_receive(BridgeState* s, const float floats[BRIDGE_FLOATS],
                                  const int32_t ints[BRIDGE_INTS], uint32_t now_ms) {
  for (int k = 0; k < BRIDGE_FLOATS; ++k) s->in_floats[k] = floats[k];
  for (int k = 0; k < BRIDGE_INTS; ++k) s->in_ints[k] = ints[k];
  const int32_t seq = ints[0];
  if (seq != s->last_seq) {
    const int32_t step = (int32_t)(((seq - s->last_seq) % BRIDGE_TICK_MODULO + BRIDGE_TICK_MODULO) %
                                   BRIDGE_TICK_MODULO);
    if (s->seen && step <= BRIDGE_SEQ_WINDOW) {
      s->frames_lost = (int32_t)((s->frames_lost + step - 1) % BRIDGE_TICK_MODULO);
    }
    s->last_seq = seq;
    s->last_new_ms = now_ms;
    s->seen = true;
  }
  bridge_command(s, now_ms);
}

// One control() at now_ms, after io() applied the command stored at the last drain: fills
// out_floats / out_ints (the echo is that command's sequence number), checks the watchdog again
// and returns the voltages for the next io() (a later drain may replace them with newer ones).
static inline BridgeVoltages bridge_control(BridgeState* s, const BridgeIO* io, uint32_t now_ms) {
  const int32_t applied_seq = s->command_seq;  // nothing drains between io() and control()
  bridge_command(s, now_ms);

  s->out_floats[0] = io->speed_a_rad_s;
  s->out_floats[1] = io->speed_b_rad_s;
  s->out_floats[2] = io->applied_a_v;
  s->out_floats[3] = io->applied_b_v;
  s->out_floats[4] = io->position_a_rad;
  s->out_floats[5] = io->position_b_rad;
  s->out_floats[BRIDGE_VERSION_CHANNEL] = (float)BRIDGE_VERSION;
  s->out_floats[7] = 0.0f;
  s->out_ints[0] = applied_seq;
  s->out_ints[1] = s->tick;
  s->out_ints[2] = (s->driving ? BRIDGE_STATUS_DRIVING : 0) | (s->tripped ? BRIDGE_STATUS_WATCHDOG : 0);
  s->out_ints[3] = s->frames_lost;
  s->tick = (int32_t)((s->tick + 1) % BRIDGE_TICK_MODULO);

  BridgeVoltages v;
  v.a_v = s->command_a_v;
  v.b_v = s->command_b_v;
  return v;
}

#endif  // CARTCTL_BRIDGE_LOGIC_H
