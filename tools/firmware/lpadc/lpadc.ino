// lpadc.ino: reference firmware for an LPADC serial ADC board
// (docs/serial-protocol.md). Two modes, chosen when it is built:
//
// - Lines (BURST 0, the default; spec v1/v2, a steady beacon): one text
//   line per sample of every channel, 20 lines/s,
//     $LPADC,<board>,<seq>,<bits>,<v0>,...,<vN-1>*<XOR hex>\r\n
// - Bursts (BURST 1; spec v3, a blinking beacon): every channel sampled at
//   SAMPLE_HZ on a hardware timer, sent in binary LPBST packets of BLOCK
//   samples. The board samples; the daemon demodulates
//   (docs/demodulator.md, "The serial board").
//
// Arduino Nano: A0..A7 (8 channels); Uno: A0..A5; Mega: A0..A15.
// Set BOARD_ID to the id configured for this board's port.

#include <Arduino.h>

#ifndef BOARD_ID
#define BOARD_ID 0
#endif

#ifndef BURST
#define BURST 0
#endif

#if defined(ARDUINO_AVR_MEGA2560)
const uint8_t NCH = 16;
#elif defined(ARDUINO_AVR_NANO)
const uint8_t NCH = 8;
#else
const uint8_t NCH = NUM_ANALOG_INPUTS;
#endif

const uint8_t BITS = 10;              // AVR ADC

#if !BURST
// ---------------------------------------------------------------- lines

const uint32_t BAUD = 115200;
const uint32_t PERIOD_US = 50000;     // 20 lines/s, faster than the daemon's 5 Hz

static uint32_t seq = 0;
static uint32_t next_us;

// XOR checksum of everything between '$' and '*'.
static uint8_t ck;

static void put(const char *s) {
  for (; *s; ++s) {
    ck ^= (uint8_t)*s;
    Serial.write(*s);
  }
}

static void put_u32(uint32_t v) {
  char buf[11];
  ultoa(v, buf, 10);
  put(buf);
}

void setup() {
  Serial.begin(BAUD);
  analogReference(DEFAULT);           // AVcc: the 5 V the reader's v_ref assumes
  for (uint8_t i = 0; i < NCH; ++i) {
    analogRead(A0 + i);               // first conversion after a mux change is discarded
  }
  next_us = micros();
}

void loop() {
  // fixed schedule: the rate does not drift with the time a line takes
  while ((int32_t)(micros() - next_us) < 0) {
  }
  next_us += PERIOD_US;

  uint16_t v[16];
  for (uint8_t i = 0; i < NCH; ++i) {
    analogRead(A0 + i);               // settle the sample-and-hold on the new input
    v[i] = analogRead(A0 + i);
  }

  ck = 0;
  Serial.write('$');
  put("LPADC,");
  put_u32(BOARD_ID);
  put(",");
  put_u32(seq++);
  put(",");
  put_u32(BITS);
  for (uint8_t i = 0; i < NCH; ++i) {
    put(",");
    put_u32(v[i]);
  }
  Serial.write('*');
  const char hex[] = "0123456789ABCDEF";
  Serial.write(hex[ck >> 4]);
  Serial.write(hex[ck & 0x0F]);
  Serial.write("\r\n");
}

#else
// --------------------------------------------------------------- bursts
//
// Timing, which the daemon's config must repeat (docs/serial-protocol.md):
// - sample i of the board's counter is taken at tick i, SAMPLE_HZ apart,
//   from Timer1 (the board's crystal: its error adds to the beacon's
//   drift, which the demodulator follows to +-100 ppm, so a ceramic
//   resonator's +-0.5 % (a Nano's, an Uno's ATmega328P) is too much: use a
//   crystal-clocked board, e.g. a Mega 2560) -> [backend] sample_hz;
// - channel c is converted (FIRST_SLOT + c) * SPACING_US after the tick,
//   paced on Timer1 (0.5 us steps) -> [backend] channel_skew_s =
//   SPACING_US * 1e-6, FIRST_SLOT = the channels of the boards listed
//   before this one;
// - boards that share the frames share the tick: the first board
//   (SYNC_MASTER 1) pulses SYNC_PIN at every tick, the others (SYNC_MASTER
//   0) take their tick from that pin. The master waits 100 ms before its
//   first tick, and a board that sees no tick for 50 ms starts its counter
//   over, so that resetting the master restarts every counter together.
//
// AVR (ATmega328P / 2560) only: Timer1 and INT0/INT4 are set up directly.

#ifndef SAMPLE_HZ
#define SAMPLE_HZ 1000
#endif
#ifndef BLOCK
#define BLOCK 16                      // samples a packet: [backend] block_samples
#endif
#ifndef SPACING_US
#define SPACING_US 60                 // two conversions at ADC clock 500 kHz (26 us each) and the code
#endif
#ifndef FIRST_SLOT
#define FIRST_SLOT 0
#endif
#ifndef SYNC_MASTER
#define SYNC_MASTER 1
#endif
#ifndef BAUD
#define BAUD 1000000UL                // 16 MHz / 16: exact on an AVR; the USB bridge must take it
#endif

const uint8_t SYNC_PIN = 2;           // INT0 on a 328P, INT4 on a 2560
const uint16_t TIMER_TOP = (uint16_t)(F_CPU / 8 / SAMPLE_HZ - 1);
const uint16_t SPACING_TICKS = SPACING_US * (F_CPU / 8 / 1000000UL);
const uint16_t FIRST_TICKS = FIRST_SLOT * SPACING_TICKS;

static_assert((uint32_t)(FIRST_SLOT + NCH) * SPACING_US < 1000000UL / SAMPLE_HZ,
              "the scan does not fit in a sample period: lower SAMPLE_HZ or SPACING_US");

// The tick: counted in the interrupt, taken by the loop.
static volatile uint32_t ticks = 0;
static volatile uint32_t last_tick_ms = 0;

#if SYNC_MASTER
ISR(TIMER1_COMPA_vect) {              // Timer1 in CTC: TCNT1 is 0 at each tick
  digitalWrite(SYNC_PIN, HIGH);
  ticks++;
  digitalWrite(SYNC_PIN, LOW);
}
#else
static void on_sync() {               // the master's tick: restart Timer1 at 0
  TCNT1 = 0;
  uint32_t now = millis();
  if (now - last_tick_ms > 50) {
    ticks = 0;                        // the master restarted: start over with it
  }
  last_tick_ms = now;
  ticks++;
}
#endif

// CRC-16/CCITT-FALSE, bitwise (no table: RAM is short).
static uint16_t crc;
static void crc_byte(uint8_t b) {
  crc ^= (uint16_t)b << 8;
  for (uint8_t i = 0; i < 8; ++i) {
    crc = (crc & 0x8000) ? (uint16_t)((crc << 1) ^ 0x1021) : (uint16_t)(crc << 1);
  }
}

// The packet being sent, written out as the UART has room between ticks.
const uint16_t PAYLOAD = ((uint32_t)BLOCK * NCH * BITS + 7) / 8;
static uint8_t tx[2 + 10 + PAYLOAD + 2];
static uint16_t tx_len = 0, tx_at = 0;

// The block being sampled.
static uint16_t block[BLOCK][16];
static uint8_t filled = 0;
static uint32_t block_first = 0;
static uint32_t next_index = 0;

static void adc_fast() {
  // ADC clock 16 MHz / 32 = 500 kHz: 26 us a conversion, ~9.5 bits of the 10.
  ADCSRA = (ADCSRA & ~0x07) | 0x05;
}

static uint16_t since_tick() {
  return TCNT1;                       // 0.5 us steps since the tick (CTC or reset by INT)
}

static void scan(uint16_t *v) {
  for (uint8_t c = 0; c < NCH; ++c) {
    uint16_t due = FIRST_TICKS + c * SPACING_TICKS;
    while (since_tick() < due) {
    }
    analogRead(A0 + c);               // the sample-and-hold settles on the new input
    v[c] = analogRead(A0 + c);
  }
}

// The block into tx: sync, header, values packed LSB first, CRC.
static void pack(uint8_t k) {
  uint16_t n = 0;
  tx[n++] = 0xA5;
  tx[n++] = 0x5A;
  uint8_t head[10] = {1, BOARD_ID, BITS, NCH, k, 0,
                      (uint8_t)block_first, (uint8_t)(block_first >> 8),
                      (uint8_t)(block_first >> 16), (uint8_t)(block_first >> 24)};
  crc = 0xFFFF;
  for (uint8_t i = 0; i < 10; ++i) {
    tx[n++] = head[i];
    crc_byte(head[i]);
  }
  uint32_t acc = 0;
  uint8_t have = 0;
  for (uint8_t i = 0; i < k; ++i) {
    for (uint8_t c = 0; c < NCH; ++c) {
      acc |= (uint32_t)block[i][c] << have;
      have += BITS;
      while (have >= 8) {
        tx[n] = (uint8_t)acc;
        crc_byte(tx[n++]);
        acc >>= 8;
        have -= 8;
      }
    }
  }
  if (have > 0) {
    tx[n] = (uint8_t)acc;
    crc_byte(tx[n++]);
  }
  tx[n++] = (uint8_t)crc;
  tx[n++] = (uint8_t)(crc >> 8);
  tx_len = n;
  tx_at = 0;
}

// A block ends full, or early when a tick was missed (its samples must be
// consecutive); a block finished while the last is still being sent is
// dropped whole: the daemon sees the gap and drops that frame.
static void finish_block() {
  if (filled == 0) {
    return;
  }
  if (tx_at >= tx_len) {
    pack(filled);
  }
  filled = 0;
}

static void send_some() {
  while (tx_at < tx_len && Serial.availableForWrite() > 0) {
    Serial.write(tx[tx_at++]);
  }
}

void setup() {
  Serial.begin(BAUD);
  analogReference(DEFAULT);
  adc_fast();
  noInterrupts();
  TCCR1A = 0;
  TCNT1 = 0;
#if SYNC_MASTER
  pinMode(SYNC_PIN, OUTPUT);
  TCCR1B = _BV(WGM12) | _BV(CS11);    // CTC on OCR1A, clock / 8
  OCR1A = TIMER_TOP;
  interrupts();
  delay(100);                         // silence: the other boards start over
  noInterrupts();
  TCNT1 = 0;
  ticks = 0;
  TIMSK1 |= _BV(OCIE1A);
#else
  pinMode(SYNC_PIN, INPUT);
  TCCR1B = _BV(CS11);                 // free running, clock / 8, zeroed by each tick
  attachInterrupt(digitalPinToInterrupt(SYNC_PIN), on_sync, RISING);
#endif
  interrupts();
}

void loop() {
  static uint32_t taken = 0;
  send_some();
  noInterrupts();
  uint32_t t = ticks;
  interrupts();
  if (t == taken) {
    return;
  }
  // Tick t - 1 is sample t - 1; a later one means ticks were missed (or
  // the counter started over): the block so far ends there.
  uint32_t index = t - 1;
  if (filled > 0 && index != next_index) {
    finish_block();
  }
  taken = t;
  if (filled == 0) {
    block_first = index;
  }
  scan(block[filled]);
  // The scan must have been of this tick's instants: one that ran into
  // the next tick (the loop held up) is not at its times. The block ends
  // before it, and the next block starts after a gap the daemon sees.
  noInterrupts();
  bool late = ticks != t;
  interrupts();
  if (late) {
    finish_block();
    return;
  }
  next_index = index + 1;
  if (++filled == BLOCK) {
    finish_block();
  }
}

#endif
