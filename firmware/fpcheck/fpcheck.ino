// fpcheck: runs single floating-point and formatting operations on the AVR for the
// differential tests of wcdrive.firmware.f32, .avrlibc and .arduino_print.
//
// The test (tests/test_avr_arithmetic.py) writes the operands and an op code into
// the globals below through the simavr harness, lets loop() run the op, and reads
// the result when doneOp() is entered. Not for a real board.
#include <Arduino.h>
#include <stdlib.h>

volatile uint8_t op = 0;        // 0 idle; see the switch below
volatile float argA = 0, argB = 0, result = 0;
volatile int32_t argInt = 0;
volatile uint8_t argDigits = 2;
char text[80];                  // strtod input, NUL-terminated
volatile int16_t consumed = 0;  // strtod: characters used
volatile char printed[40];      // printFloat output (volatile: only the harness reads it)
volatile uint8_t printedLen = 0;

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

void setup() {}

void loop() {
  uint8_t which = op;
  if (which == 0) return;
  float a = argA, b = argB;
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
