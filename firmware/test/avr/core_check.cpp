// The core's arithmetic on the AVR itself: prints "CORE_CHECK <checksum>" on UART0 (simavr
// shows it), for tests/firmware/test_fw_avr.py to compare with the host build's checksum.
#include <avr/interrupt.h>
#include <avr/io.h>
#include <avr/sleep.h>

#include "../core_check_seq.h"

static void put(char c) {
    while (!(UCSR0A & _BV(UDRE0))) {
    }
    UDR0 = (uint8_t)c;
}

int main() {
    UCSR0A = _BV(U2X0);
    UBRR0 = 1;  // 1 Mbaud at 16 MHz
    UCSR0B = _BV(TXEN0);
    const uint32_t h = utrf::check::core_check_run();
    const char* s = "CORE_CHECK ";
    while (*s) put(*s++);
    for (int8_t i = 7; i >= 0; --i) put("0123456789abcdef"[(h >> (4 * i)) & 0xF]);
    put('\n');
    while (!(UCSR0A & _BV(TXC0))) {
    }
    cli();
    sleep_enable();
    sleep_cpu();  // simavr stops here
    return 0;
}
