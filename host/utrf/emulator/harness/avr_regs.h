/* ATmega2560 register addresses and bit numbers, from avr-libc's own <avr/iom2560.h>.
 *
 * The harness runs on the host, so the avr-libc header is read with its access macros
 * redefined to plain numbers: _SFR_IO8(x) becomes the data-space address x + 0x20, as in
 * simavr's core definitions. Build with -idirafter /usr/lib/avr/include so the host's own
 * headers win for everything else.
 */
#ifndef UTRF_AVR_REGS_H
#define UTRF_AVR_REGS_H

#define _AVR_IO_H_
#define __ASSEMBLER__ 1
#ifndef __AVR_ATmega2560__
#define __AVR_ATmega2560__
#endif
#define _SFR_IO8(v) ((v) + 0x20)
#define _SFR_IO16(v) ((v) + 0x20)
#define _SFR_MEM8(v) (v)
#define _SFR_MEM16(v) (v)
#define _SFR_MEM32(v) (v)
#define _VECTOR(v) (v)
#include <avr/iom2560.h>
#undef __ASSEMBLER__

#endif /* UTRF_AVR_REGS_H */
