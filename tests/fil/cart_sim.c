/*
 * cart_sim: the MECOtron cart around a firmware image, in real time, for cartctl's
 * firmware-in-the-loop test (tests/test_firmware_fil.py).
 *
 * The ELF runs on simavr's ATmega2560 at 16 MHz. Its cycle counter is paced against
 * CLOCK_MONOTONIC, so one simulated second takes one second of wall time (the harness sleeps when
 * the AVR is ahead; when the host machine cannot keep up, the AVR falls behind and the report
 * says by how much). Around it:
 *
 *   - UART0 <-> a pseudo-terminal. The slave's path is the first line on stdout. Bytes from the
 *     PC reach the AVR's receiver one byte time apart at the line's baud rate (--baud, 10 bits a
 *     byte), as on a wire. The receiver is the ATmega's: a two-byte buffer and the shift register;
 *     a byte is lost (data overrun, counted) when the next start bit comes while the buffer is
 *     still full. simavr 1.6 does not model this: it counts a parity bit in every byte time, shows
 *     a byte one byte time late, and raises the receive interrupt once per byte time however many
 *     wait; the harness corrects the byte time and requests the interrupt itself (see
 *     rxc_request). Bytes the AVR sends reach the PC when their stop bit has gone out.
 *     --usb-latency adds the Mega's ATmega16U2 USB bridge: cart -> PC bytes wait in it until its
 *     4.096 ms timer overflows or more than 96 wait, then go out in the next 1 ms USB frame;
 *     PC -> cart bytes leave in the next 1 ms frame.
 *   - Two DC motors with wheels (the cartctl "ground" preset: electrical and mechanical equation,
 *     viscous and Coulomb friction, the cart's inertia and rolling friction), driven through a
 *     model of the TB6612FNG H-bridge from the pins of the course template: PWM duty from Timer4
 *     (OC4B pin 7 for motor A, OC4C pin 8 for motor B), direction IN1/IN2 on pins 4/5 (A) and
 *     9/10 (B), standby on pin 6 (OC4A). The average voltage over a PWM period drives the motor.
 *   - Quadrature encoders on pins 2/11 (A) and 3/12 (B): 448 cycles, 1792 edges, per wheel
 *     revolution, each edge at the cycle the wheel passes it. Motor A is mounted mirrored: a
 *     positive voltage turns it forward, and its encoder counts down (the template's scale for A
 *     is negative). Encoder B starts --encoder-phase counts (default 0.5) from A, so that two
 *     wheels turning alike do not interrupt at the same instants all the time.
 *
 * --realtime asks for SCHED_FIFO priority 20 (below cartctl's loop), so that a busy machine
 * delays the simulation less; the report says whether it was granted.
 *
 * At exit (SIGINT, SIGTERM or --seconds), and on SIGUSR1 without stopping, it writes a JSON report
 * (--report, default stdout):
 * the AVR's cycles and the wall time they took, the bytes each way and those dropped, the time of
 * the host's last byte and of the moment both motors lost their voltage after it, and more. Each
 * time the motors get a voltage after both had none, a line "drive T" (AVR seconds) goes to
 * stdout. --log writes the true wheel speeds, voltages and currents every ms as CSV.
 * CART_SIM_DEBUG=1 prints the interrupts and bytes before each overrun to stderr; 2 also every
 * GPIO frame each way.
 *
 * Build: gcc -O2 -I/usr/include/simavr cart_sim.c -lsimavr -lm -lutil (Debian: libsimavr-dev)
 * All of it is cartctl's own code; it uses simavr (GPL-3) as a library.
 */

#define _GNU_SOURCE
#include <errno.h>
#include <fcntl.h>
#include <getopt.h>
#include <math.h>
#include <pty.h>
#include <sched.h>
#include <signal.h>
#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/ioctl.h>
#include <termios.h>
#include <time.h>
#include <unistd.h>

#include "avr_extint.h"
#include "avr_ioport.h"
#include "avr_uart.h"
#include "sim_avr.h"
#include "sim_cycle_timers.h"
#include "sim_elf.h"
#include "sim_interrupts.h"
#include "sim_irq.h"

DEFINE_FIFO(uint16_t, uart_fifo); /* the accessors of the UART's input FIFO (simavr's header) */

#define F_CPU 16000000ULL
#define CYCLES_PER_MS (F_CPU / 1000)
#define PHYS_STEP_CYCLES 320 /* 20 us: the motors' integration step */
#define IO_SLICE_CYCLES 1600 /* 100 us: the pty is served, and the clock checked, this often */
#define LOG_EVERY_STEPS 50   /* the optional log: one line a ms */
#define TWO_PI 6.283185307179586

/* ATmega2560 data-space addresses of the registers the model reads. */
#define REG_TCCR4A 0xA0
#define REG_TCCR4B 0xA1
#define REG_ICR4L 0xA6
#define REG_OCR4AL 0xA8
#define REG_OCR4BL 0xAA
#define REG_OCR4CL 0xAC
#define REG_UCSR0A 0xC0
#define REG_UCSR0B 0xC1
#define REG_UCSR0C 0xC2
#define REG_UBRR0L 0xC4
#define REG_UBRR0H 0xC5

/* ------------------------------------------------------------------------------------------ */
/* options and state                                                                           */

static double opt_seconds = 0.0; /* 0: until a signal */
static long opt_baud = 500000;
static int opt_usb = 0;
static const char *opt_report = NULL;
static const char *opt_log = NULL;
static double opt_phase_b = 0.5;
static int opt_realtime = 0, realtime_granted = 0;

static volatile sig_atomic_t stop_requested = 0;
static volatile sig_atomic_t snapshot_requested = 0;
static unsigned report_seq = 0;
static avr_t *avr;
static avr_uart_t *uart0;
static uint64_t byte_cycles; /* one byte on the line: 10 bit times */
static int pty_master = -1, pty_slave = -1;
static FILE *log_file;

typedef struct {
  uint8_t byte;
  uint64_t at;      /* PC -> cart: ready to leave; cart -> PC: stop bit out of the AVR */
  uint64_t deliver; /* cart -> PC: when the PC gets it (0: not decided yet) */
} qbyte_t;

#define QSIZE (1u << 16)
typedef struct {
  qbyte_t q[QSIZE];
  uint32_t head, tail; /* head: next out; tail: next free */
} queue_t;

static queue_t to_avr, to_pc;
static uint32_t usb_next; /* to_pc: next byte the 16U2 model has not taken in */

static struct {
  uint64_t host_bytes_read;      /* from the pty */
  uint64_t host_bytes_to_avr;    /* through the line into the AVR's receiver */
  uint64_t rx_overruns;          /* dropped: the receiver's data overrun */
  uint64_t rx_disabled_drops;    /* dropped: the AVR's receiver was off */
  uint64_t cart_bytes;           /* written by the AVR */
  uint64_t pc_bytes_written;     /* into the pty */
  uint64_t pc_bytes_discarded;   /* the pty was full: nobody reading on the PC side */
  uint64_t queue_overflows;      /* harness queues full (should stay 0) */
  int64_t last_host_read_cycle;  /* -1: none */
  int64_t last_host_byte_cycle;  /* stop bit of the host's last byte into the AVR; -1: none */
  int64_t last_nonzero_cycle;    /* last step with a voltage on either motor; -1: never */
  int64_t zero_since_cycle;      /* first step with both at 0 V after it */
  uint64_t drive_episodes;       /* times the motors got a voltage after both had none */
  double max_lag_s;              /* how far the AVR fell behind the wall clock */
  double max_lag_at_s;           /* when (AVR time) */
  double lag_over_1ms_s;         /* AVR time spent more than 1 ms behind */
  uint64_t usb_flushes_timer, usb_flushes_full;
} st = {.last_host_read_cycle = -1, .last_host_byte_cycle = -1, .last_nonzero_cycle = -1};

static int rx_line_busy = 0;   /* the line-feeding cycle timer is registered */
static uint64_t rx_line_free;  /* PC -> cart: the line is free from this cycle */
static uint64_t tx_line_free;  /* cart -> PC */
static int uart_xoff = 0;

/* ------------------------------------------------------------------------------------------ */
/* the motors                                                                                  */

typedef struct {
  /* the cartctl "ground" preset (src/cartctl/plants/physics_params.py), at the wheel */
  double J, b, tc, K, R, L;
  /* state */
  double i, w, theta;
  double v;          /* average voltage over the PWM period at this step */
  int coast;         /* both bridge outputs off (standby, or IN1 = IN2 = low) */
  int enc_sign;      /* encoder counts per forward count: -1 for the mirrored motor A */
  int64_t enc_count; /* edges the encoder has produced (signed) */
  double enc_phase;  /* the encoder's offset from the wheel's zero, in counts */
  int64_t enc_scheduled; /* the count after the edges already scheduled */
  struct { uint64_t at; int64_t count; } edges[256]; /* scheduled edges, in time order */
  unsigned edge_head, edge_tail;
  int edge_timer_on;
  /* pins: encoder channels (port letter, bit) */
  char enc_a_port, enc_b_port;
  int enc_a_bit, enc_b_bit;
  avr_irq_t *enc_a_irq, *enc_b_irq;
  /* bridge inputs: IN1, IN2 (port, bit); PWM on Timer4 channel (1 = B, 2 = C) */
  char in1_port, in2_port;
  int in1_bit, in2_bit, ocr_channel;
  double max_abs_w;
} motor_t;

static motor_t motors[2];
static uint64_t phys_steps;
static double stby_level_last = 0.0;

static void motor_init(motor_t *m, int enc_sign) {
  m->J = 8.76e-4 + 6.679e-4; /* rotor and gearbox + the cart's share (ground) */
  m->b = 6.8e-4;
  m->tc = 0.05 + 0.09023; /* Coulomb + rolling friction */
  m->K = 0.4476;
  m->R = 3.0;
  m->L = 6.38e-3;
  m->enc_sign = enc_sign;
}

static uint8_t port_reg(char port, int which) {
  /* which: 0 PIN, 1 DDR, 2 PORT; data-space addresses of the ATmega2560 */
  uint16_t base;
  switch (port) {
    case 'B': base = 0x23; break;
    case 'E': base = 0x2C; break;
    case 'G': base = 0x32; break;
    case 'H': base = 0x100; break;
    default: return 0;
  }
  return avr->data[base + which];
}

static int port_out_high(char port, int bit) {
  /* an output pin driving high; an input (floating) counts as low */
  return ((port_reg(port, 1) >> bit) & 1) && ((port_reg(port, 2) >> bit) & 1);
}

static uint16_t reg16(uint16_t low) { return (uint16_t)(avr->data[low] | (avr->data[low + 1] << 8)); }

/* The level of a Timer4 output pin as a duty in [0, 1]: the waveform when its compare output is
 * connected, the PORT bit when not. channel 0, 1, 2 = OC4A (pin 6), OC4B (pin 7), OC4C (pin 8). */
static double timer4_pin_duty(int channel) {
  static const int bits[3] = {3, 4, 5}; /* PH3, PH4, PH5 */
  int bit = bits[channel];
  if (!((port_reg('H', 1) >> bit) & 1)) return 0.0; /* input: the bridge sees low */
  uint8_t tccra = avr->data[REG_TCCR4A], tccrb = avr->data[REG_TCCR4B];
  int com = (tccra >> (6 - 2 * channel)) & 3;
  if (com < 2) return ((port_reg('H', 2) >> bit) & 1) ? 1.0 : 0.0; /* not connected (or toggle) */
  int wgm = (tccra & 3) | ((tccrb >> 1) & 0x0C);
  uint16_t ocr = reg16(REG_OCR4AL + 2 * channel);
  double top;
  int fast;
  switch (wgm) {
    case 1: top = 255; fast = 0; break;  /* phase correct 8-bit (the Arduino core's set-up) */
    case 2: top = 511; fast = 0; break;
    case 3: top = 1023; fast = 0; break;
    case 5: top = 255; fast = 1; break;  /* fast PWM 8-bit */
    case 6: top = 511; fast = 1; break;
    case 7: top = 1023; fast = 1; break;
    case 8: case 10: top = reg16(REG_ICR4L); fast = 0; break;
    case 9: case 11: top = reg16(REG_OCR4AL); fast = 0; break;
    case 14: top = reg16(REG_ICR4L); fast = 1; break;
    case 15: top = reg16(REG_OCR4AL); fast = 1; break; /* the template's 62.5 kHz set-up */
    default: return ((port_reg('H', 2) >> bit) & 1) ? 1.0 : 0.0;
  }
  if ((tccrb & 7) == 0) return 0.0; /* timer stopped: take the output as low */
  double duty;
  if (top <= 0) duty = 1.0;
  else if (fast) duty = ocr >= top ? 1.0 : (ocr + 1.0) / (top + 1.0); /* set at BOTTOM, clear at match */
  else duty = ocr >= top ? 1.0 : ocr / top;
  if (com == 3) duty = 1.0 - duty; /* inverting */
  return duty;
}

/* TB6612FNG: IN1/IN2 = H/L forward, L/H reverse, H/H short brake, L/L off; PWM low = short
 * brake; STBY low = off. The average output voltage over a PWM period. */
static void bridge_voltage(motor_t *m, double stby) {
  int in1 = port_out_high(m->in1_port, m->in1_bit);
  int in2 = port_out_high(m->in2_port, m->in2_bit);
  double pwm = timer4_pin_duty(m->ocr_channel);
  m->coast = 0;
  if (stby < 0.5 || (!in1 && !in2)) {
    m->coast = 1;
    m->v = 0.0;
  } else if (in1 && in2) {
    m->v = 0.0; /* short brake */
  } else {
    m->v = (in1 ? 12.0 : -12.0) * pwm;
  }
}

static void encoder_set_pins(motor_t *m, int a, int b) {
  avr_raise_irq(m->enc_a_irq, a);
  avr_raise_irq(m->enc_b_irq, b);
}

/* The quadrature state for a count, in the order the firmware's Encoder library counts up:
 * (B, A) = 00 -> 10 -> 11 -> 01 -> 00. Count 0 is (1, 1), both high, what the pull-ups show. */
static void encoder_levels(int64_t count, int *a, int *b) {
  int phase = (int)((((count + 2) % 4) + 4) % 4);
  *b = (phase == 1 || phase == 2);
  *a = (phase == 2 || phase == 3);
}

static uint8_t ext_value[8]; /* external pin levels per port ('A' + k), for simavr's pull-ups */
static uint8_t ext_mask[8];

static void ext_update(char port, int bit, int level) {
  int k = port - 'A';
  ext_mask[k] |= (uint8_t)(1 << bit);
  if (level) ext_value[k] |= (uint8_t)(1 << bit);
  else ext_value[k] &= (uint8_t)~(1 << bit);
  avr_ioport_external_t e = {.name = (unsigned)port, .mask = ext_mask[k], .value = ext_value[k]};
  avr_ioctl(avr, AVR_IOCTL_IOPORT_SET_EXTERNAL(port), &e);
}

static void encoder_emit(motor_t *m, int64_t count) {
  int a, b;
  encoder_levels(count, &a, &b);
  /* simavr drives an input pin whose PORT bit is set (a pull-up) high whenever the firmware
   * writes that PORT, unless an "external" level is set for it: keep that level the encoder's */
  ext_update(m->enc_a_port, m->enc_a_bit, a);
  ext_update(m->enc_b_port, m->enc_b_bit, b);
  encoder_set_pins(m, a, b);
}

static avr_cycle_count_t edge_cb(avr_t *a, avr_cycle_count_t when, void *param) {
  (void)a;
  motor_t *m = (motor_t *)param;
  while (m->edge_head != m->edge_tail && m->edges[m->edge_head % 256].at <= when) {
    m->enc_count = m->edges[m->edge_head % 256].count;
    encoder_emit(m, m->enc_count);
    m->edge_head++;
  }
  if (m->edge_head == m->edge_tail) {
    m->edge_timer_on = 0;
    return 0;
  }
  return m->edges[m->edge_head % 256].at;
}

/* The encoder's position in counts (fractional) for a wheel angle. */
static double encoder_position(const motor_t *m, double theta) {
  return m->enc_sign * theta * 1792.0 / TWO_PI + m->enc_phase;
}

/* Advances one motor from `when` by one step of dt, with the voltage the bridge has now, and
 * schedules the encoder edges at the cycles the wheel passes them (the angle taken as linear in
 * time over the step). */
static void motor_step(motor_t *m, double dt, uint64_t when) {
  if (m->coast) {
    m->i = 0.0; /* bridge outputs off: no current (the flyback through the diodes ignored) */
  } else {
    m->i += dt * (m->v - m->R * m->i - m->K * m->w) / m->L;
  }
  double torque = m->K * m->i - m->b * m->w;
  double w0 = m->w, theta0 = m->theta;
  if (m->w == 0.0) {
    if (fabs(torque) > m->tc) m->w = dt * (torque - copysign(m->tc, torque)) / m->J;
  } else {
    double w1 = m->w + dt * (torque - copysign(m->tc, m->w)) / m->J;
    m->w = (w1 * m->w < 0.0) ? 0.0 : w1; /* friction stops it, never reverses it */
  }
  m->theta += 0.5 * (w0 + m->w) * dt;
  if (fabs(m->w) > m->max_abs_w) m->max_abs_w = fabs(m->w);
  double x0 = encoder_position(m, theta0), x1 = encoder_position(m, m->theta);
  int64_t target = (int64_t)floor(x1);
  while (m->enc_scheduled != target && m->edge_tail - m->edge_head < 256) {
    int up = target > m->enc_scheduled;
    int64_t next = m->enc_scheduled + (up ? 1 : -1);
    double boundary = (double)(up ? next : m->enc_scheduled); /* the count changes there */
    double f = x1 != x0 ? (boundary - x0) / (x1 - x0) : 1.0;
    if (f < 0.0) f = 0.0;
    if (f > 1.0) f = 1.0;
    uint64_t at = when + (uint64_t)(f * PHYS_STEP_CYCLES);
    if (m->edge_tail != m->edge_head && at < m->edges[(m->edge_tail - 1) % 256].at)
      at = m->edges[(m->edge_tail - 1) % 256].at;
    m->edges[m->edge_tail % 256].at = at;
    m->edges[m->edge_tail % 256].count = next;
    m->edge_tail++;
    m->enc_scheduled = next;
  }
  if (!m->edge_timer_on && m->edge_head != m->edge_tail) {
    uint64_t at = m->edges[m->edge_head % 256].at, now = avr->cycle;
    avr_cycle_timer_register(avr, at > now ? at - now : 1, edge_cb, m);
    m->edge_timer_on = 1;
  }
}

static avr_cycle_count_t physics_cb(avr_t *a, avr_cycle_count_t when, void *param) {
  (void)a;
  (void)param;
  double dt = (double)PHYS_STEP_CYCLES / F_CPU;
  double stby = timer4_pin_duty(0);
  stby_level_last = stby;
  for (int k = 0; k < 2; ++k) bridge_voltage(&motors[k], stby);
  int nonzero = fabs(motors[0].v) > 1e-9 || fabs(motors[1].v) > 1e-9;
  if (nonzero) {
    if (st.last_nonzero_cycle < 0 || st.zero_since_cycle > st.last_nonzero_cycle) {
      st.drive_episodes++;
      printf("drive %.6f\n", (double)when / F_CPU); /* a drive episode starts */
      fflush(stdout);
    }
    st.last_nonzero_cycle = (int64_t)when;
  } else if (st.last_nonzero_cycle >= 0 && st.zero_since_cycle <= st.last_nonzero_cycle) {
    st.zero_since_cycle = (int64_t)when;
  }
  for (int k = 0; k < 2; ++k) motor_step(&motors[k], dt, when);
  if (log_file && phys_steps % LOG_EVERY_STEPS == 0) {
    fprintf(log_file, "%.4f,%.4f,%.4f,%.4f,%.4f,%.4f,%.4f\n", (double)when / F_CPU, motors[0].w,
            motors[1].w, motors[0].v, motors[1].v, motors[0].i, motors[1].i);
  }
  phys_steps++;
  return when + PHYS_STEP_CYCLES;
}

/* ------------------------------------------------------------------------------------------ */
/* the line, PC -> cart                                                                        */

static int queue_push(queue_t *q, uint8_t byte, uint64_t at) {
  if (q->tail - q->head >= QSIZE) {
    st.queue_overflows++;
    return 0;
  }
  qbyte_t *e = &q->q[q->tail % QSIZE];
  e->byte = byte;
  e->at = at;
  e->deliver = 0;
  q->tail++;
  return 1;
}

/* The cycle at which the next waiting byte's stop bit is in (its start: when it is ready and
 * the line is free). */
static uint64_t rx_next_start(void) {
  qbyte_t *e = &to_avr.q[to_avr.head % QSIZE];
  return e->at > rx_line_free ? e->at : rx_line_free;
}

static uint64_t rx_next_end(void) { return rx_next_start() + byte_cycles; }

/* The ATmega's RXC interrupt is a level: it stays requested while unread bytes wait. simavr 1.6
 * requests it once per byte time from its own timer and drops the request when the handler
 * starts, so after a late handler the waiting bytes trickle in one per byte time and the next
 * ones overrun, which the ATmega does not do. Request it again when a byte completes, and at the
 * end of each handler while bytes wait (its limit on reading "faster than the line" kept off:
 * the line's pace is this harness's). */
/* CART_SIM_DEBUG=1: the interrupts and bytes before each overrun go to stderr */
static int debug = 0; /* 1: overruns, 2: and every GPIO frame */
static struct {
  uint64_t cycle;
  uint32_t value; /* the vector starting (0: a handler returned), or the byte completing */
  uint32_t pc;
  int kind; /* 1 interrupt, 2 byte into the receiver */
} trace[64];
static unsigned trace_count;

static void trace_add(int kind, uint32_t value) {
  unsigned k = trace_count++ % 64;
  trace[k].cycle = avr->cycle;
  trace[k].kind = kind;
  trace[k].value = value;
  trace[k].pc = avr->pc;
}

static void trace_interrupt_cb(avr_irq_t *irq, uint32_t value, void *param) {
  (void)irq;
  (void)param;
  trace_add(1, value);
}

static void trace_dump(void) {
  for (unsigned k = trace_count > 64 ? trace_count - 64 : 0; k < trace_count; ++k) {
    unsigned j = k % 64;
    fprintf(stderr, "  %llu %s %u pc 0x%x\n", (unsigned long long)trace[j].cycle,
            trace[j].kind == 1 ? "vector" : "byte", trace[j].value, trace[j].pc);
  }
}

static void rxc_request(void) {
  uart0->rxc_raise_time = 0;
  avr_raise_interrupt(avr, &uart0->rxc);
}

static int shift_held;
static uint8_t shift_byte;
static uint64_t rx_next_start(void);
static void rx_deliver(uint8_t byte);
static void rx_overrun(const char *why);

/* At the end of each receive handler: the byte in the shift register moves into the buffer if
 * the handler made room before the next byte's start bit, and RXC is requested again while bytes
 * wait. */
static void rxc_running_cb(avr_irq_t *irq, uint32_t value, void *param) {
  (void)irq;
  (void)param;
  if (value != 0 || !avr_regbit_get(avr, uart0->rxen)) return;
  if (shift_held && uart_fifo_get_read_size(&uart0->input) < 2) {
    shift_held = 0;
    if (to_avr.head != to_avr.tail && rx_next_start() <= avr->cycle) rx_overrun("late handler");
    else rx_deliver(shift_byte);
  }
  if (!uart_fifo_isempty(&uart0->input)) rxc_request();
}

/* shift_held, shift_byte: the byte the receiver's shift register holds because its two-byte
 * buffer was full, if any. */

/* CART_SIM_DEBUG: a MAVLink 1 GPIO frame's ints, each way, with the time, to stderr */
typedef struct {
  uint8_t buf[64];
  int n;
} sniffer_t;
static sniffer_t sniff_in, sniff_out;

static void sniff(sniffer_t *s, uint8_t byte, const char *who) {
  if (s->n == 0 && byte != 0xFE) return;
  s->buf[s->n++] = byte;
  if (s->n >= 2 && s->n == s->buf[1] + 8) {
    if (s->buf[5] == 3 && s->buf[1] == 52) {
      int32_t ints[4];
      memcpy(ints, s->buf + 6 + 4 + 32, sizeof ints);
      fprintf(stderr, "%s %.6f gpio ints %d %d %d %d\n", who, (double)avr->cycle / F_CPU,
              ints[0], ints[1], ints[2], ints[3]);
    }
    s->n = 0;
  } else if (s->n >= 64) {
    s->n = 0;
  }
}

static void rx_deliver(uint8_t byte) {
  if (debug > 1) sniff(&sniff_in, byte, "host");
  avr_raise_irq(avr_io_getirq(avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_INPUT), byte);
  /* simavr 1.6 would show the byte one byte time later: it is complete now, so RXC now */
  rxc_request();
  if (debug) trace_add(2, byte);
  st.host_bytes_to_avr++;
}

static void rx_overrun(const char *why) {
  st.rx_overruns++;
  if (debug) {
    fprintf(stderr, "overrun (%s) at cycle %llu: pc 0x%x, I %d\n", why,
            (unsigned long long)avr->cycle, (unsigned)avr->pc, avr->sreg[S_I]);
    trace_dump();
  }
}

/* The ATmega's receiver: a completed byte goes into the two-byte buffer; when that is full it
 * waits in the shift register, and is lost (data overrun) when the next byte's start bit comes
 * before the buffer has room. */
static avr_cycle_count_t rx_line_cb(avr_t *a, avr_cycle_count_t when, void *param) {
  (void)param;
  if (to_avr.head == to_avr.tail) {
    rx_line_busy = 0;
    return 0;
  }
  qbyte_t *e = &to_avr.q[to_avr.head % QSIZE];
  to_avr.head++;
  rx_line_free = when;
  st.last_host_byte_cycle = (int64_t)when;
  if (shift_held) { /* this byte's start bit came while the one before still waited */
    shift_held = 0;
    rx_overrun("start bit");
  }
  if (!(avr_regbit_get(a, uart0->rxen))) {
    st.rx_disabled_drops++;
  } else if (uart_xoff || uart_fifo_get_read_size(&uart0->input) >= 2) {
    shift_held = 1;
    shift_byte = e->byte;
  } else {
    rx_deliver(e->byte);
  }
  if (to_avr.head == to_avr.tail) {
    rx_line_busy = 0;
    return 0;
  }
  return rx_next_end();
}

static void rx_line_kick(void) {
  if (rx_line_busy || to_avr.head == to_avr.tail) return;
  uint64_t end = rx_next_end();
  uint64_t now = avr->cycle;
  avr_cycle_timer_register(avr, end > now ? end - now : 1, rx_line_cb, NULL);
  rx_line_busy = 1;
}

static void uart_xon_cb(avr_irq_t *irq, uint32_t value, void *param) {
  (void)irq;
  (void)param;
  if (value) uart_xoff = 0;
}

static void uart_xoff_cb(avr_irq_t *irq, uint32_t value, void *param) {
  (void)irq;
  (void)param;
  uart_xoff = value != 0;
}

static uint64_t next_usb_frame(uint64_t t) { return (t / CYCLES_PER_MS + 1) * CYCLES_PER_MS; }

/* ------------------------------------------------------------------------------------------ */
/* the line, cart -> PC, and the 16U2                                                          */

static void uart_out_cb(avr_irq_t *irq, uint32_t value, void *param) {
  (void)irq;
  (void)param;
  uint64_t now = avr->cycle;
  uint64_t start = now > tx_line_free ? now : tx_line_free;
  tx_line_free = start + byte_cycles;
  st.cart_bytes++;
  if (debug > 1) sniff(&sniff_out, (uint8_t)value, "cart");
  if (queue_push(&to_pc, (uint8_t)value, tx_line_free) && !opt_usb)
    to_pc.q[(to_pc.tail - 1) % QSIZE].deliver = tx_line_free;
}

#define USB_T0_PERIOD 65536ULL /* the 16U2's Timer0: 16 MHz / 256 / 256 = 4.096 ms */
#define USB_NEARLY_FULL 96
static uint64_t usb_next_t0 = USB_T0_PERIOD;
static uint32_t usb_buffer_start; /* to_pc index of the first byte in the 16U2's buffer */

static void usb_flush(uint32_t end, uint64_t at) {
  uint64_t frame = next_usb_frame(at);
  for (uint32_t k = usb_buffer_start; k != end; ++k) to_pc.q[k % QSIZE].deliver = frame;
  usb_buffer_start = end;
}

/* Runs the 16U2 model up to now: bytes enter its buffer at their stop bit; it sends what it holds
 * at each overflow of its Timer0, or at once when more than 96 wait. */
static void usb_advance(uint64_t now) {
  for (;;) {
    uint64_t next_byte = usb_next != to_pc.tail ? to_pc.q[usb_next % QSIZE].at : UINT64_MAX;
    if (next_byte <= now && next_byte <= usb_next_t0) {
      usb_next++;
      if (usb_next - usb_buffer_start > USB_NEARLY_FULL) {
        usb_flush(usb_next, next_byte);
        st.usb_flushes_full++;
      }
      continue;
    }
    if (usb_next_t0 <= now) {
      if (usb_next != usb_buffer_start) {
        usb_flush(usb_next, usb_next_t0);
        st.usb_flushes_timer++;
      }
      usb_next_t0 += USB_T0_PERIOD;
      continue;
    }
    break;
  }
}

/* simavr 1.6 times a UART frame as start + data + a parity bit + stop bits, with or without
 * parity: 11 bit times for 8N1 instead of 10, so the AVR could take bytes only 10 % slower than
 * the line brings them. Put the true frame length back whenever the firmware has set the UART. */
static void uart_fix_byte_time(void) {
  uint16_t ubrr = (uint16_t)(avr->data[REG_UBRR0L] | ((avr->data[REG_UBRR0H] & 0x0F) << 8));
  uint8_t a = avr->data[REG_UCSR0A], b = avr->data[REG_UCSR0B], c = avr->data[REG_UCSR0C];
  uint32_t cycles_per_bit = (ubrr + 1u) * ((a & 0x02) ? 8u : 16u);
  int size = ((c >> 1) & 3) | (b & 0x04);
  int data_bits = size <= 3 ? 5 + size : (size == 7 ? 9 : 8);
  int parity = ((c >> 4) & 3) ? 1 : 0;
  int stop = (c & 0x08) ? 2 : 1;
  uart0->cycles_per_byte = cycles_per_bit * (uint32_t)(1 + data_bits + parity + stop);
}

/* ------------------------------------------------------------------------------------------ */
/* the pseudo-terminal                                                                         */

static void pty_serve(void) {
  uint64_t now = avr->cycle;
  uart_fix_byte_time();
  uint8_t buffer[4096];
  for (;;) {
    ssize_t n = read(pty_master, buffer, sizeof buffer);
    if (n <= 0) break; /* EAGAIN: nothing; EIO: nobody has the slave open (we keep it open) */
    uint64_t ready = opt_usb ? next_usb_frame(now) : now;
    for (ssize_t k = 0; k < n; ++k) queue_push(&to_avr, buffer[k], ready);
    st.host_bytes_read += (uint64_t)n;
    st.last_host_read_cycle = (int64_t)now;
  }
  rx_line_kick();

  if (opt_usb) usb_advance(now);
  uint32_t end = to_pc.head;
  while (end != to_pc.tail && to_pc.q[end % QSIZE].deliver && to_pc.q[end % QSIZE].deliver <= now)
    end++;
  while (to_pc.head != end) {
    uint32_t count = 0;
    while (to_pc.head + count != end && count < sizeof buffer) {
      buffer[count] = to_pc.q[(to_pc.head + count) % QSIZE].byte;
      count++;
    }
    ssize_t n = write(pty_master, buffer, count);
    if (n < 0 && errno == EAGAIN) {
      /* nobody reads on the PC side and the pty is full: what a closed port would lose */
      tcflush(pty_slave, TCIFLUSH);
      n = write(pty_master, buffer, count);
      if (n < 0) n = 0;
      st.pc_bytes_discarded += count - (uint32_t)n;
      to_pc.head += count;
      st.pc_bytes_written += (uint64_t)n;
      continue;
    }
    if (n <= 0) break;
    to_pc.head += (uint32_t)n;
    st.pc_bytes_written += (uint64_t)n;
  }
}

/* ------------------------------------------------------------------------------------------ */
/* the report                                                                                  */

static double wall_now(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return (double)ts.tv_sec + ts.tv_nsec * 1e-9;
}

static void json_time(FILE *f, const char *name, int64_t cycle, int comma) {
  if (cycle < 0) fprintf(f, "  \"%s\": null", name);
  else fprintf(f, "  \"%s\": %.6f", name, (double)cycle / F_CPU);
  fputs(comma ? ",\n" : "\n", f);
}

static void write_report(double wall_s) {
  FILE *f = stdout;
  char partial[4096];
  if (opt_report) {
    snprintf(partial, sizeof partial, "%s.partial", opt_report);
    f = fopen(partial, "w");
    if (!f) {
      perror(opt_report);
      f = stdout;
    }
  }
  double avr_s = (double)avr->cycle / F_CPU;
  uint16_t ubrr = (uint16_t)(avr->data[REG_UBRR0L] | ((avr->data[REG_UBRR0H] & 0x0F) << 8));
  int u2x = (avr->data[REG_UCSR0A] >> 1) & 1;
  double uart_baud = (double)F_CPU / ((u2x ? 8.0 : 16.0) * (ubrr + 1));
  int64_t watchdog_cycles = -1;
  int running = st.last_nonzero_cycle >= 0 && st.zero_since_cycle <= st.last_nonzero_cycle;
  fprintf(f, "{\n  \"report\": %u,\n", ++report_seq);
  fprintf(f, "  \"baud\": %ld,\n  \"firmware_uart_baud\": %.1f,\n", opt_baud, uart_baud);
  fprintf(f, "  \"usb_latency\": %s,\n", opt_usb ? "true" : "false");
  fprintf(f, "  \"sched_fifo\": %s,\n", realtime_granted ? "true" : "false");
  fprintf(f, "  \"encoder_phase_b\": %.3f,\n", opt_phase_b);
  fprintf(f, "  \"avr_cycles\": %llu,\n", (unsigned long long)avr->cycle);
  fprintf(f, "  \"avr_seconds\": %.6f,\n  \"wall_seconds\": %.6f,\n", avr_s, wall_s);
  fprintf(f, "  \"realtime_factor\": %.6f,\n", wall_s > 0 ? avr_s / wall_s : 0.0);
  fprintf(f, "  \"max_lag_ms\": %.3f,\n  \"max_lag_at_s\": %.3f,\n", st.max_lag_s * 1e3,
          st.max_lag_at_s);
  fprintf(f, "  \"lag_over_1ms_s\": %.3f,\n", st.lag_over_1ms_s);
  fprintf(f, "  \"avr_state\": %d,\n  \"avr_pc\": %u,\n", avr->state, (unsigned)avr->pc);
  fprintf(f, "  \"host_bytes_read\": %llu,\n", (unsigned long long)st.host_bytes_read);
  fprintf(f, "  \"host_bytes_to_avr\": %llu,\n", (unsigned long long)st.host_bytes_to_avr);
  fprintf(f, "  \"bytes_dropped\": %llu,\n",
          (unsigned long long)(st.rx_overruns + st.rx_disabled_drops + st.queue_overflows));
  fprintf(f, "  \"rx_overruns\": %llu,\n", (unsigned long long)st.rx_overruns);
  fprintf(f, "  \"rx_disabled_drops\": %llu,\n", (unsigned long long)st.rx_disabled_drops);
  fprintf(f, "  \"queue_overflows\": %llu,\n", (unsigned long long)st.queue_overflows);
  fprintf(f, "  \"cart_bytes\": %llu,\n", (unsigned long long)st.cart_bytes);
  fprintf(f, "  \"pc_bytes_written\": %llu,\n", (unsigned long long)st.pc_bytes_written);
  fprintf(f, "  \"pc_bytes_discarded\": %llu,\n", (unsigned long long)st.pc_bytes_discarded);
  fprintf(f, "  \"usb_flushes_timer\": %llu,\n  \"usb_flushes_full\": %llu,\n",
          (unsigned long long)st.usb_flushes_timer, (unsigned long long)st.usb_flushes_full);
  json_time(f, "last_host_read_s", st.last_host_read_cycle, 1);
  json_time(f, "last_host_byte_s", st.last_host_byte_cycle, 1);
  json_time(f, "last_voltage_s", st.last_nonzero_cycle, 1);
  json_time(f, "motors_zero_s", running || st.last_nonzero_cycle < 0 ? -1 : st.zero_since_cycle, 1);
  if (!running && st.last_nonzero_cycle >= 0 && st.last_host_byte_cycle >= 0)
    watchdog_cycles = st.zero_since_cycle - st.last_host_byte_cycle;
  if (running || st.last_nonzero_cycle < 0 || st.last_host_byte_cycle < 0)
    fprintf(f, "  \"watchdog_ms\": null,\n");
  else fprintf(f, "  \"watchdog_ms\": %.3f,\n", (double)watchdog_cycles / CYCLES_PER_MS);
  (void)watchdog_cycles;
  fprintf(f, "  \"motors_running_at_exit\": %s,\n", running ? "true" : "false");
  fprintf(f, "  \"drive_episodes\": %llu,\n", (unsigned long long)st.drive_episodes);
  fprintf(f, "  \"standby_pin_duty\": %.4f,\n", stby_level_last);
  const char *names[2] = {"a", "b"};
  fprintf(f, "  \"motors\": {\n");
  for (int k = 0; k < 2; ++k) {
    motor_t *m = &motors[k];
    fprintf(f,
            "    \"%s\": {\"speed_rad_s\": %.5f, \"position_rad\": %.5f, \"voltage_v\": %.5f, "
            "\"current_a\": %.5f, \"encoder_count\": %lld, \"max_abs_speed_rad_s\": %.5f}%s\n",
            names[k], m->w, m->theta, m->v, m->i, (long long)m->enc_count, m->max_abs_w,
            k == 0 ? "," : "");
  }
  fprintf(f, "  }\n}\n");
  if (f != stdout) {
    fclose(f);
    rename(partial, opt_report); /* a reader never sees half a report */
  } else {
    fflush(f);
  }
}

/* ------------------------------------------------------------------------------------------ */

static void on_signal(int sig) {
  if (sig == SIGUSR1) snapshot_requested = 1;
  else stop_requested = 1;
}

static void usage(const char *argv0) {
  fprintf(stderr,
          "usage: %s FIRMWARE.elf [--baud N] [--seconds S] [--usb-latency] [--report PATH] "
          "[--log PATH] [--encoder-phase COUNTS] [--realtime]\n",
          argv0);
}

/* simavr's messages go to stderr, errors only: stdout carries the pty's path and the events */
static void quiet_logger(avr_t *a, const int level, const char *format, va_list ap) {
  (void)a;
  if (level <= LOG_ERROR) vfprintf(stderr, format, ap);
}

static avr_irq_t *pin_irq(char port, int bit) {
  return avr_io_getirq(avr, AVR_IOCTL_IOPORT_GETIRQ(port), bit);
}

int main(int argc, char **argv) {
  static const struct option options[] = {
      {"baud", required_argument, NULL, 'b'},   {"seconds", required_argument, NULL, 's'},
      {"usb-latency", no_argument, NULL, 'u'},  {"report", required_argument, NULL, 'r'},
      {"log", required_argument, NULL, 'l'},    {"help", no_argument, NULL, 'h'},
      {"encoder-phase", required_argument, NULL, 'p'},
      {"realtime", no_argument, NULL, 't'},
      {NULL, 0, NULL, 0}};
  int c;
  while ((c = getopt_long(argc, argv, "", options, NULL)) != -1) {
    switch (c) {
      case 'b': opt_baud = strtol(optarg, NULL, 10); break;
      case 's': opt_seconds = strtod(optarg, NULL); break;
      case 'u': opt_usb = 1; break;
      case 'r': opt_report = optarg; break;
      case 'l': opt_log = optarg; break;
      case 'p': opt_phase_b = strtod(optarg, NULL); break;
      case 't': opt_realtime = 1; break;
      default: usage(argv[0]); return 2;
    }
  }
  if (optind != argc - 1 || opt_baud <= 0) {
    usage(argv[0]);
    return 2;
  }
  byte_cycles = (10 * F_CPU + (uint64_t)opt_baud / 2) / (uint64_t)opt_baud;

  avr_global_logger_set(quiet_logger);
  elf_firmware_t firmware;
  memset(&firmware, 0, sizeof firmware);
  if (elf_read_firmware(argv[optind], &firmware) != 0) {
    fprintf(stderr, "cart_sim: cannot read %s\n", argv[optind]);
    return 1;
  }
  avr = avr_make_mcu_by_name("atmega2560");
  if (!avr) {
    fprintf(stderr, "cart_sim: simavr has no atmega2560\n");
    return 1;
  }
  avr_init(avr);
  avr->log = LOG_ERROR;
  firmware.frequency = F_CPU;
  avr_load_firmware(avr, &firmware);
  avr->frequency = F_CPU;

  /* UART0: no console echo, no sleeping in the status-register poll */
  uint32_t flags = 0;
  avr_ioctl(avr, AVR_IOCTL_UART_SET_FLAGS('0'), &flags);
  for (avr_io_t *io = avr->io_port; io; io = io->next)
    if (!strcmp(io->kind, "uart") && ((avr_uart_t *)io)->name == '0') uart0 = (avr_uart_t *)io;
  if (!uart0) {
    fprintf(stderr, "cart_sim: no UART0\n");
    return 1;
  }
  avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_OUTPUT),
                          uart_out_cb, NULL);
  avr_irq_register_notify(uart0->rxc.irq + AVR_INT_IRQ_RUNNING, rxc_running_cb, NULL);
  debug = getenv("CART_SIM_DEBUG") ? atoi(getenv("CART_SIM_DEBUG")) : 0;
  if (debug) avr_irq_register_notify(avr->interrupts.irq + AVR_INT_IRQ_RUNNING, trace_interrupt_cb, NULL);
  avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_OUT_XON),
                          uart_xon_cb, NULL);
  avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_OUT_XOFF),
                          uart_xoff_cb, NULL);

  /* motors: A = IN1 4 (PG5), IN2 5 (PE3), PWM 7 (OC4B), encoder 2 (PE4) / 11 (PB5), mirrored;
   *         B = IN1 9 (PH6), IN2 10 (PB4), PWM 8 (OC4C), encoder 3 (PE5) / 12 (PB6) */
  motor_init(&motors[0], -1);
  motor_init(&motors[1], +1);
  motors[1].enc_phase = opt_phase_b;
  motors[0].in1_port = 'G'; motors[0].in1_bit = 5;
  motors[0].in2_port = 'E'; motors[0].in2_bit = 3;
  motors[0].ocr_channel = 1;
  motors[0].enc_a_port = 'E'; motors[0].enc_a_bit = 4;
  motors[0].enc_b_port = 'B'; motors[0].enc_b_bit = 5;
  motors[1].in1_port = 'H'; motors[1].in1_bit = 6;
  motors[1].in2_port = 'B'; motors[1].in2_bit = 4;
  motors[1].ocr_channel = 2;
  motors[1].enc_a_port = 'E'; motors[1].enc_a_bit = 5;
  motors[1].enc_b_port = 'B'; motors[1].enc_b_bit = 6;
  /* simavr keeps polling an INTn pin that went low while INTn was set to low-level mode (the
   * reset state, before the firmware picks CHANGE), and raises the interrupt for as long as it is
   * low, whatever the mode later: the encoders start high and the polling is off. */
  avr_extint_set_strict_lvl_trig(avr, 4, 0);
  avr_extint_set_strict_lvl_trig(avr, 5, 0);
  for (int k = 0; k < 2; ++k) {
    motors[k].enc_a_irq = pin_irq(motors[k].enc_a_port, motors[k].enc_a_bit);
    motors[k].enc_b_irq = pin_irq(motors[k].enc_b_port, motors[k].enc_b_bit);
    motors[k].enc_count = motors[k].enc_scheduled = (int64_t)floor(motors[k].enc_phase);
    encoder_emit(&motors[k], motors[k].enc_count);
  }

  if (opt_log) {
    log_file = fopen(opt_log, "w");
    if (!log_file) {
      perror(opt_log);
      return 1;
    }
    fprintf(log_file, "t_s,speed_a_rad_s,speed_b_rad_s,voltage_a_v,voltage_b_v,current_a_a,"
                      "current_b_a\n");
  }

  if (openpty(&pty_master, &pty_slave, NULL, NULL, NULL) != 0) {
    perror("openpty");
    return 1;
  }
  struct termios raw;
  tcgetattr(pty_slave, &raw);
  cfmakeraw(&raw);
  tcsetattr(pty_slave, TCSANOW, &raw); /* no echo or line editing before the host sets it up */
  fcntl(pty_master, F_SETFL, fcntl(pty_master, F_GETFL) | O_NONBLOCK);
  printf("%s\n", ttyname(pty_slave));
  fflush(stdout);

  struct sigaction sa;
  memset(&sa, 0, sizeof sa);
  sa.sa_handler = on_signal;
  sigaction(SIGINT, &sa, NULL);
  sigaction(SIGTERM, &sa, NULL);
  sigaction(SIGUSR1, &sa, NULL);
  signal(SIGPIPE, SIG_IGN);

  avr_cycle_timer_register(avr, PHYS_STEP_CYCLES, physics_cb, NULL);

  if (opt_realtime) { /* SCHED_FIFO below cartctl's own loop (50), when the system allows it */
    struct sched_param param = {.sched_priority = 20};
    realtime_granted = sched_setscheduler(0, SCHED_FIFO, &param) == 0;
  }

  double t0 = wall_now();
  uint64_t next_slice = IO_SLICE_CYCLES;
  int state = cpu_Running;
  while (!stop_requested) {
    while (avr->cycle < next_slice) {
      state = avr_run(avr);
      if (state == cpu_Done || state == cpu_Crashed) break;
    }
    if (state == cpu_Done || state == cpu_Crashed) {
      fprintf(stderr, "cart_sim: the AVR stopped (state %d) at %.3f s\n", state,
              (double)avr->cycle / F_CPU);
      break;
    }
    next_slice = avr->cycle + IO_SLICE_CYCLES;
    pty_serve();
    double avr_s = (double)avr->cycle / F_CPU;
    double wall_s = wall_now() - t0;
    double ahead = avr_s - wall_s;
    if (-ahead > st.max_lag_s) {
      st.max_lag_s = -ahead;
      st.max_lag_at_s = avr_s;
    }
    if (-ahead > 1e-3) st.lag_over_1ms_s += (double)IO_SLICE_CYCLES / F_CPU;
    if (ahead > 50e-6) {
      struct timespec ts = {.tv_sec = (time_t)ahead, .tv_nsec = (long)((ahead - floor(ahead)) * 1e9)};
      nanosleep(&ts, NULL);
    }
    if (snapshot_requested) {
      snapshot_requested = 0;
      write_report(wall_now() - t0);
    }
    if (opt_seconds > 0 && wall_now() - t0 >= opt_seconds) break;
  }
  double wall_s = wall_now() - t0;
  if (log_file) fclose(log_file);
  write_report(wall_s);
  close(pty_master);
  close(pty_slave);
  return 0;
}
