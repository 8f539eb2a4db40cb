/* Read-only tables in flash: PROGMEM and pgm_read on the AVR, plain memory on the host.
 *
 * The generated kinematics table includes this file, so it stays C/C++ compatible and
 * free of Arduino headers.
 */
#ifndef UTRF_HAL_PROGMEM_H
#define UTRF_HAL_PROGMEM_H

#include <stdint.h>

#if defined(__AVR__)
#include <avr/pgmspace.h>
#define UTRF_PROGMEM PROGMEM
static inline int16_t utrf_pgm_read_i16(const int16_t* p) {
    return (int16_t)pgm_read_word(p);
}
static inline uint8_t utrf_pgm_read_u8(const uint8_t* p) { return pgm_read_byte(p); }
#else
#define UTRF_PROGMEM
static inline int16_t utrf_pgm_read_i16(const int16_t* p) { return *p; }
static inline uint8_t utrf_pgm_read_u8(const uint8_t* p) { return *p; }
#endif

#endif /* UTRF_HAL_PROGMEM_H */
