// hapkit_nanopush: reference firmware for the `serial` backend of nanopush-haptic.
//
// Board: Hapkit 3 class (ATmega328P at 16 MHz, Arduino Uno compatible). A magnetoresistive (MR)
// sensor on A2 reads a magnet on the motor pulley; the pulley turns several times over the
// sector's travel, so its reading wraps and the wraps ("flips") are counted. The motor driver
// takes PWM on pin 5 and the direction on pin 8. Optional buttons, each from its pin to GND:
// engage on pin 2, clutch on pin 4.
//
// Protocol version 1, as haptic-bridge/src/serial/ and haptic-bridge/README.md document it:
// fixed-length little-endian packets, sync 0xA5, a kind byte, the version, CRC-16/CCITT-FALSE
// (poly 0x1021, init 0xFFFF) of the bytes before it at the end.
//   host -> device  force 'F' 12 bytes: flags (bit 0 active, bit 1 hello), seq u16, force i32 uN
//   device -> host  state 'S' 24 bytes: status, echo u16, seq u16, position i32 um,
//                   velocity i32 um/s, buttons, reserved, rendered force i32 uN
//   device -> host  info  'I' 32 bytes: reserved, echo u16, seq u16, max force i32 uN,
//                   travel i32 um x2, max stiffness u32 mN/m, max damping u32 mN.s/m, rate u16 Hz
// Each valid force packet is answered at once: a hello with an info packet, any other with a
// state packet. No valid force packet for HOST_SILENCE_MS: the force is zeroed (and the next
// state packet says so, STATUS_HOST_SILENT).
//
// Position zero is where the handle is when the board starts, and the board restarts whenever
// the host opens the port (DTR reset): hold the handle at the centre of its travel then.
//
// Timer0 runs without a prescaler for a 62.5 kHz (inaudible) PWM on pin 5, which makes millis(),
// micros() and delay() run 64 times fast: this sketch does not use them; Timer1 gives the 1 kHz tick.

#include <avr/interrupt.h>
#include <avr/wdt.h>
#include <math.h>

// ---- Protocol (kept equal to haptic-bridge/src/serial/; a Rust test checks these lines) ----
const uint8_t SYNC = 0xA5;
const uint8_t KIND_FORCE = 'F';
const uint8_t KIND_STATE = 'S';
const uint8_t KIND_INFO = 'I';
const uint8_t PROTOCOL_VERSION = 1;
const uint8_t FORCE_LEN = 12;
const uint8_t STATE_LEN = 24;
const uint8_t INFO_LEN = 32;
const uint16_t CRC_POLY = 0x1021;
const uint16_t CRC_INIT = 0xFFFF;
const uint8_t FLAG_ACTIVE = 0x01;
const uint8_t FLAG_HELLO = 0x02;
const uint8_t STATUS_HOST_SILENT = 0x01;
const uint8_t STATUS_FORCE_LIMITED = 0x02;
const uint32_t HOST_SILENCE_MS = 10;
// 1000000 baud is exact for a 16 MHz AVR and carries a 36-byte exchange in 0.36 ms, so the
// bridge's 1 kHz fits (at 115200 an exchange takes 3.1 ms: too slow, the bridge refuses it).
// The bridge opens serial:PATH at 1000000 unless told PATH@BAUD.
const uint32_t BAUD = 1000000;
const uint16_t LOOP_HZ = 1000;

// ---- Pins (Hapkit 3) ----
const uint8_t PWM_PIN = 5;  // Timer0 OC0B
const uint8_t DIR_PIN = 8;
const uint8_t MR_PIN = A2;
const uint8_t ENGAGE_PIN = 2;  // to GND when pressed (internal pull-up)
const uint8_t CLUTCH_PIN = 4;  // to GND when held (internal pull-up)

// ---- Kinematics: Hapkit 3 nominal values; measure your own device ----
const float HANDLE_RADIUS_M = 0.090;     // rh: pivot to the grip on the handle
const float SECTOR_RADIUS_M = 0.073152;  // rs: pivot to the capstan cable on the sector
const float PULLEY_RADIUS_M = 0.004191;  // rp: motor pulley
// Sector angle per flip-counted MR count (degrees); calibrate: move the handle through a known
// angle and divide by the change in counts.
const float MR_DEG_PER_COUNT = -0.0107;
const int FLIP_THRESHOLD = 700;   // a jump over two samples larger than this is a wrap
const int COUNTS_PER_FLIP = 980;  // counts added per counted wrap
const float POSITION_SIGN = 1.0;  // -1 if moving the handle up reads negative
const float FORCE_SIGN = 1.0;     // -1 if a positive force pushes the handle down

// ---- Motor and limits ----
const float MOTOR_TORQUE_NM = 0.03;  // pulley torque at 100 % duty, stalled
const float MAX_FORCE_N = 3.0;       // the clamp on every command (the motor could give ~5.8 N)
const float CONT_FORCE_N = 1.5;      // what the motor takes continuously
const float PEAK_SECONDS = 5.0;      // the full force for this long trips the thermal limit
const float TRAVEL_MIN_M = -0.040;   // end stops, 0 at the centre
const float TRAVEL_MAX_M = 0.040;
const float MAX_STIFFNESS_N_PER_M = 400.0;  // renders stably at 1 kHz
const float MAX_DAMPING_NS_PER_M = 1.5;
const float VELOCITY_FILTER_HZ = 40.0;  // first-order low-pass on the differentiated position

// A hardware watchdog resets the board (motor pins float: no force) if this loop ever stalls.
// Set to 0 for a bootloader older than Optiboot, which does not survive a watchdog reset.
#define USE_HW_WATCHDOG 1

const float DT = 1.0 / LOOP_HZ;
const float HEAT_LIMIT = (MAX_FORCE_N * MAX_FORCE_N - CONT_FORCE_N * CONT_FORCE_N) * PEAK_SECONDS;

volatile uint8_t tickCount = 0;  // 8 bits: read atomically
uint8_t lastTick = 0;
uint32_t nowMs = 0;

// Sensing.
int lastRaw = 0, lastLastRaw = 0;
long flips = 0;
bool flipped = false;
long countsAtStart = 0;
float positionM = 0, velocityMs = 0, velocityAlpha = 0;
uint8_t buttons = 0;

// Force.
bool commandActive = false;
float commandN = 0;     // as commanded, clamped
float renderedN = 0;    // after the thermal limit and the watchdog
float heat = 0;         // N^2 s above the continuous rating
bool thermalLimited = false;
uint32_t lastHostMs = 0;
uint8_t statusLatch = 0;  // reported once, in the next state packet

// Protocol.
uint8_t rx[FORCE_LEN];
uint8_t rxLen = 0;
uint16_t lastEcho = 0;
uint16_t deviceSeq = 0;

ISR(TIMER1_COMPA_vect) { tickCount++; }

uint16_t crc16(const uint8_t *p, uint8_t n) {
  uint16_t crc = CRC_INIT;
  while (n--) {
    crc ^= (uint16_t)(*p++) << 8;
    for (uint8_t i = 0; i < 8; i++) {
      crc = (crc & 0x8000) ? (uint16_t)((crc << 1) ^ CRC_POLY) : (uint16_t)(crc << 1);
    }
  }
  return crc;
}

void put16(uint8_t *b, uint16_t v) {
  b[0] = v & 0xFF;
  b[1] = v >> 8;
}

void put32(uint8_t *b, uint32_t v) {
  for (uint8_t i = 0; i < 4; i++) b[i] = (v >> (8 * i)) & 0xFF;
}

uint16_t get16(const uint8_t *b) { return (uint16_t)b[0] | ((uint16_t)b[1] << 8); }

uint32_t get32(const uint8_t *b) {
  return (uint32_t)b[0] | ((uint32_t)b[1] << 8) | ((uint32_t)b[2] << 16) | ((uint32_t)b[3] << 24);
}

void sendPacket(uint8_t *b, uint8_t len, uint8_t kind, uint8_t byte3) {
  b[0] = SYNC;
  b[1] = kind;
  b[2] = PROTOCOL_VERSION;
  b[3] = byte3;
  put16(b + len - 2, crc16(b, len - 2));
  Serial.write(b, len);
}

void sendState() {
  uint8_t b[STATE_LEN] = {0};
  uint8_t status = statusLatch | (thermalLimited ? STATUS_FORCE_LIMITED : 0);
  statusLatch = 0;
  put16(b + 4, lastEcho);
  put16(b + 6, deviceSeq++);
  put32(b + 8, (uint32_t)lround(positionM * 1e6));
  put32(b + 12, (uint32_t)lround(velocityMs * 1e6));
  b[16] = buttons;
  put32(b + 18, (uint32_t)lround(renderedN * 1e6));
  sendPacket(b, STATE_LEN, KIND_STATE, status);
}

void sendInfo(uint16_t echo) {
  uint8_t b[INFO_LEN] = {0};
  put16(b + 4, echo);
  put16(b + 6, deviceSeq++);
  put32(b + 8, (uint32_t)lround(MAX_FORCE_N * 1e6));
  put32(b + 12, (uint32_t)lround(TRAVEL_MIN_M * 1e6));
  put32(b + 16, (uint32_t)lround(TRAVEL_MAX_M * 1e6));
  put32(b + 20, (uint32_t)lround(MAX_STIFFNESS_N_PER_M * 1e3));
  put32(b + 24, (uint32_t)lround(MAX_DAMPING_NS_PER_M * 1e3));
  put16(b + 28, LOOP_HZ);
  sendPacket(b, INFO_LEN, KIND_INFO, 0);
}

// Sets the motor to the commanded force, within the clamp and the thermal limit.
void renderForce() {
  float limit = thermalLimited ? CONT_FORCE_N : MAX_FORCE_N;
  float f = commandActive ? constrain(commandN, -limit, limit) : 0.0;
  float pulleyTorque = f * HANDLE_RADIUS_M * PULLEY_RADIUS_M / SECTOR_RADIUS_M;
  float duty = fabs(pulleyTorque) / MOTOR_TORQUE_NM;
  if (duty > 1.0) duty = 1.0;
  digitalWrite(DIR_PIN, f * FORCE_SIGN > 0 ? HIGH : LOW);
  analogWrite(PWM_PIN, (int)(duty * 255.0 + 0.5));
  renderedN = f;
}

void onForcePacket() {
  uint8_t flags = rx[3];
  uint16_t seq = get16(rx + 4);
  if (flags & FLAG_HELLO) {
    // Answered whatever the version, so the host can name a mismatch; renders nothing.
    commandActive = false;
    commandN = 0;
    renderForce();
    lastHostMs = nowMs;
    sendInfo(seq);
    return;
  }
  if (rx[2] != PROTOCOL_VERSION) return;  // not applied, not answered
  int32_t un = (int32_t)get32(rx + 6);
  const int32_t maxUn = (int32_t)lround(MAX_FORCE_N * 1e6);
  if (un > maxUn) un = maxUn;
  if (un < -maxUn) un = -maxUn;
  commandActive = (flags & FLAG_ACTIVE) != 0;
  commandN = commandActive ? un * 1e-6 : 0.0;
  lastHostMs = nowMs;
  lastEcho = seq;
  renderForce();
  sendState();
}

// One received byte into the force-packet parser; resyncs on the sync byte.
void feedByte(uint8_t b) {
  if (rxLen == 0 && b != SYNC) return;
  if (rxLen == 1 && b != KIND_FORCE) {
    rxLen = (b == SYNC) ? 1 : 0;
    return;
  }
  rx[rxLen++] = b;
  if (rxLen < FORCE_LEN) return;
  if (crc16(rx, FORCE_LEN - 2) == get16(rx + FORCE_LEN - 2)) {
    rxLen = 0;
    onForcePacket();
    return;
  }
  // Bad checksum: drop the sync byte and look again in what follows it (a packet cut short
  // leaves the next packet's head there). Fewer than FORCE_LEN bytes: no recursion.
  uint8_t rest[FORCE_LEN - 1];
  uint8_t n = rxLen - 1;
  memcpy(rest, rx + 1, n);
  rxLen = 0;
  for (uint8_t i = 0; i < n; i++) feedByte(rest[i]);
}

void pollSerial() {
  while (Serial.available() > 0) feedByte((uint8_t)Serial.read());
}

void sensePosition() {
  int raw = analogRead(MR_PIN);
  // Over two samples, so a wrap read with one sample half-way is still seen.
  int diff2 = raw - lastLastRaw;
  lastLastRaw = lastRaw;
  lastRaw = raw;
  if (abs(diff2) > FLIP_THRESHOLD && !flipped) {
    flips += diff2 > 0 ? -1 : 1;
    flipped = true;  // the next two-sample difference spans the same wrap
  } else {
    flipped = false;
  }
  long counts = raw + flips * COUNTS_PER_FLIP;
  float sectorRad = MR_DEG_PER_COUNT * (counts - countsAtStart) * (M_PI / 180.0);
  float x = POSITION_SIGN * HANDLE_RADIUS_M * sectorRad;
  velocityMs += velocityAlpha * ((x - positionM) / DT - velocityMs);
  positionM = x;
}

void controlStep() {
  sensePosition();
  buttons = (digitalRead(ENGAGE_PIN) == LOW ? 0x01 : 0) | (digitalRead(CLUTCH_PIN) == LOW ? 0x02 : 0);
  if (commandActive && nowMs - lastHostMs > HOST_SILENCE_MS) {
    commandActive = false;
    commandN = 0;
    statusLatch |= STATUS_HOST_SILENT;
  }
  // I^2 t: heat builds above the continuous rating and drains below it.
  heat += (renderedN * renderedN - CONT_FORCE_N * CONT_FORCE_N) * DT;
  if (heat < 0) heat = 0;
  if (heat > HEAT_LIMIT) thermalLimited = true;
  if (heat < HEAT_LIMIT / 2) thermalLimited = false;
  renderForce();
}

void setup() {
  wdt_disable();
  pinMode(PWM_PIN, OUTPUT);
  pinMode(DIR_PIN, OUTPUT);
  analogWrite(PWM_PIN, 0);
  pinMode(ENGAGE_PIN, INPUT_PULLUP);
  pinMode(CLUTCH_PIN, INPUT_PULLUP);
  TCCR0B = (TCCR0B & 0xF8) | 0x01;  // Timer0 without prescaler: 62.5 kHz PWM on pin 5

  // The start position is zero.
  lastRaw = analogRead(MR_PIN);
  lastLastRaw = lastRaw;
  countsAtStart = lastRaw;
  velocityAlpha = 1.0 - exp(-2.0 * M_PI * VELOCITY_FILTER_HZ * DT);

  // Timer1, CTC, prescaler 64: LOOP_HZ ticks.
  noInterrupts();
  TCCR1A = 0;
  TCCR1B = _BV(WGM12) | _BV(CS11) | _BV(CS10);
  OCR1A = F_CPU / 64 / LOOP_HZ - 1;
  TIMSK1 = _BV(OCIE1A);
  interrupts();

  Serial.begin(BAUD);
#if USE_HW_WATCHDOG
  wdt_enable(WDTO_60MS);
#endif
}

void loop() {
  pollSerial();
  uint8_t t = tickCount;
  if (t != lastTick) {
    nowMs += (uint8_t)(t - lastTick);
    lastTick = t;
    controlStep();
#if USE_HW_WATCHDOG
    wdt_reset();
#endif
  }
}
