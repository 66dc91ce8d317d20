// fpcheck: runs single floating-point and formatting operations on the AVR for the
// differential tests of wcdrive.avr.f32, .avrlibc and .arduino_print.
//
// The test (tests/avr/test_avr_arithmetic.py) writes the operands and an op code into
// the globals below through the simavr harness, lets loop() run the op, and reads
// the result when doneOp() is entered. Not for a real board.
#include <Arduino.h>
#include <stdlib.h>
#include <string.h>

volatile uint8_t op = 0;        // 0 idle; see the switch below
volatile float argA = 0, argB = 0, result = 0;
volatile int32_t argInt = 0;
volatile uint8_t argDigits = 2;
char text[80];                  // strtod input, NUL-terminated
volatile int16_t consumed = 0;  // strtod: characters used
volatile char printed[40];      // printFloat output (volatile: only the harness reads it)
volatile uint8_t printedLen = 0;

// Batch mode (op 0x80 | code): the harness writes batchN operand pairs as raw binary32
// (or int32/uint32) words into batchA/batchB; loop() runs the operation on every pair
// and writes each result word to batchR. One simavr crossing per 256 pairs.
#define BATCH 256
volatile uint32_t batchA[BATCH], batchB[BATCH], batchR[BATCH];
volatile uint16_t batchN = 0;

class Capture : public Print {
 public:
  size_t write(uint8_t c) override {
    if (printedLen < sizeof(printed)) printed[printedLen++] = (char)c;
    return 1;
  }
};
static Capture capture;

extern "C" __attribute__((noinline)) void doneOp(uint8_t which) {
  asm volatile("" ::"r"(which));
}

static inline float asFloat(uint32_t w) {
  float f;
  memcpy(&f, &w, 4);
  return f;
}

static inline uint32_t asWord(float f) {
  uint32_t w;
  memcpy(&w, &f, 4);
  return w;
}

// One batch: the operations the sketch's ELF calls (__addsf3, __subsf3, __mulsf3,
// __divsf3, __cmpsf2/__ltsf2/__lesf2/__eqsf2/__nesf2, __gtsf2/__gesf2, __unordsf2,
// __fixsfsi, __fixunssfsi, __floatsisf, __floatunsisf).
static __attribute__((noinline)) void runBatch(uint8_t code) {
  uint16_t n = batchN;
  if (n > BATCH) n = BATCH;
  for (uint16_t i = 0; i < n; i++) {
    volatile float a = asFloat(batchA[i]), b = asFloat(batchB[i]);
    uint32_t r = 0;
    switch (code) {
      case 1: r = asWord(a / b); break;
      case 2: r = asWord(a * b); break;
      case 3: r = asWord(a + b); break;
      case 4: r = asWord(a - b); break;
      case 9:  // every C comparison, one bit each
        r = (uint32_t)((a < b) ? 1 : 0) | ((a <= b) ? 2 : 0) | ((a > b) ? 4 : 0) |
            ((a >= b) ? 8 : 0) | ((a == b) ? 16 : 0) | ((a != b) ? 32 : 0) |
            (__builtin_isunordered(a, b) ? 64 : 0);
        break;
      case 10: r = (uint32_t)(int32_t)a; break;
      case 11: r = (uint32_t)a; break;
      case 12: r = asWord((float)(int32_t)batchA[i]); break;
      case 13: r = asWord((float)batchA[i]); break;
    }
    batchR[i] = r;
  }
}

void setup() {}

void loop() {
  uint8_t which = op;
  if (which == 0) return;
  float a = argA, b = argB;
  if (which & 0x80) {
    runBatch(which & 0x7F);
    op = 0;
    doneOp(which);
    return;
  }
  switch (which) {
    case 1: result = a / b; break;
    case 2: result = a * b; break;
    case 3: result = a + b; break;
    case 4: result = a - b; break;
    case 5: {
      char* end;
      result = (float)strtod(text, &end);
      consumed = (int16_t)(end - text);
      break;
    }
    case 6:
      printedLen = 0;
      capture.print(a, argDigits);
      break;
    case 7: result = (float)argInt; break;
    case 8: argInt = (int32_t)a; break;
  }
  op = 0;
  doneOp(which);
}
