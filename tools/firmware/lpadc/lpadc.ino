// lpadc.ino: reference firmware for an LPADC serial ADC board
// (docs/serial-protocol.md). Streams all analog inputs as
//   $LPADC,<board>,<seq>,<bits>,<v0>,...,<vN-1>*<XOR hex>\r\n
// at a fixed rate, so that lightposed's serial backend can make frames.
//
// Arduino Nano: A0..A7 (8 channels); Uno: A0..A5; Mega: A0..A15.
// Set BOARD_ID to the id configured for this board's port.

#include <Arduino.h>

#ifndef BOARD_ID
#define BOARD_ID 0
#endif

#if defined(ARDUINO_AVR_MEGA2560)
const uint8_t NCH = 16;
#elif defined(ARDUINO_AVR_NANO)
const uint8_t NCH = 8;
#else
const uint8_t NCH = NUM_ANALOG_INPUTS;
#endif

const uint8_t BITS = 10;              // AVR ADC
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
