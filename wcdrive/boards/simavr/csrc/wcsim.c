/*
 * wcsim: a lock-step harness over libsimavr (Debian simavr 1.6) that turns a
 * compiled Mega 2560 ELF into a virtual board driven from Python (ctypes).
 *
 * Deterministic: nothing here looks at the wall clock. Stimulus (pin levels,
 * UART bytes) is queued at exact cycles and applied at the first instruction
 * boundary at or after its cycle; every UART TX byte is stamped with the cycle
 * at which the firmware wrote it; entries to chosen functions (by flash byte
 * address) are logged with the cycle and the argument registers r22..r25.
 *
 * The USART0 receiver is the harness's (see rx_arrive): the chip's two-frame FIFO and
 * shift register, with data overrun (DOR0) when the firmware reads too late, where
 * simavr 1.6 queues 64 bytes and never overruns. Every byte lost is logged. (The bare
 * chip of wcsim_new_chip, the bootloader stand-in, keeps simavr's queue and feeds it
 * with flow control, wcsim_feed: what avrdude talks to.)
 *
 * Resets (wcsim_reset: DTR/external, brown-out, power-on; and the AVR watchdog's own)
 * restart the core without stopping the clock: the cycle count runs on, so queued
 * stimulus and logs keep their meaning. MCUSR shows the cause as the hardware's does;
 * the pins driven from outside keep their levels; every reset is logged.
 *
 * Analog inputs: the ADC's channels 0..7 take millivolts (event kind 2), which simavr
 * keeps across resets; it samples lazily, at the firmware's read of ADCL, scaled by
 * AVcc (5 V here, as on an Arduino Mega: WCSIM_SUPPLY_MV).
 *
 * Compiled on first use by wcdrive/boards/simavr/build.py into libwcsim.so (gcc, -lsimavr -lelf).
 */
#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <simavr/sim_avr.h>
#include <simavr/sim_elf.h>
#include <simavr/sim_io.h>
#include <simavr/sim_irq.h>
#include <simavr/sim_vcd_file.h>
#include <simavr/avr_adc.h>
#include <simavr/avr_ioport.h>
#include <simavr/avr_uart.h>
#include <simavr/avr_watchdog.h>
#include <simavr/avr_extint.h>
#include <simavr/avr_eeprom.h>

#define WCSIM_MAX_HOOKS 16
/* The ATmega2560's interrupt response: 5 cycles from the flag to the vector (3-byte PC). */
#define WCSIM_IRQ_ENTRY_CYCLES 5
/* The board's supply, AVcc and AREF (mV): an Arduino Mega's 5 V. simavr 1.6 takes the
 * ADC's AVcc reference from avr->avcc (3.3 V, with a warning, when it is 0). */
#define WCSIM_SUPPLY_MV 5000
/* The ADC channels simavr 1.6 keeps a value for (adc_values[8]). */
#define WCSIM_ADC_CHANNELS 8

typedef struct {
    uint64_t cycle;
    uint8_t kind;   /* 0 pin, 1 uart byte, 2 analog input */
    uint8_t port;   /* 'A'.. for pins */
    uint8_t bit;    /* the pin's bit; the ADC channel for an analog input */
    uint16_t value; /* the level, the byte, or the analog input's millivolts */
} wcsim_event_t;

typedef struct {
    uint64_t cycle;
    uint8_t byte;
} wcsim_tx_t;

typedef struct {
    uint64_t cycle;
    uint32_t hook;   /* index into hooks */
    uint32_t arg;    /* r22..r25 little-endian */
    uint8_t r24;
} wcsim_hit_t;

/* Reset causes: what wcsim_reset takes (all but WATCHDOG) and the reset log reports. */
enum {
    WCSIM_RESET_POWER_ON = 0,
    WCSIM_RESET_EXTERNAL = 1,   /* the RESET pin: DTR on an Arduino, the reset button */
    WCSIM_RESET_BROWN_OUT = 2,
    WCSIM_RESET_WATCHDOG = 3,   /* the AVR's WDT expired in reset mode */
};

typedef struct {
    uint64_t cycle;
    uint8_t cause;
    uint8_t mcusr;   /* MCUSR right after the reset */
} wcsim_reset_t;

/* A byte the USART0 receiver lost: its cycle, its index among the bytes that reached the
 * receiver (0 the first), its value and why: 0 overrun (DOR0), 1 receiver disabled. */
typedef struct {
    uint64_t cycle;
    uint64_t index;
    uint8_t byte;
    uint8_t why;
} wcsim_rx_lost_t;

/* USART0's receive side as the ATmega2560 has it (datasheet, "Receiving Frames"): a
 * two-frame FIFO read through UDR0 and the receive shift register. data[0..1] are the
 * FIFO, data[2] the frame waiting in the shift register; dor[i] the DOR0 flag stored with
 * frame i. */
typedef struct {
    uint8_t data[3];
    uint8_t dor[3];
    uint8_t n;
} wcsim_rx_t;

/* Ports 'A'..'L' by letter - 'A': the input levels driven from outside. */
#define WCSIM_PORTS 12

typedef struct {
    avr_t *avr;
    elf_firmware_t fw;
    /* stimulus queue, kept sorted by cycle (stable for equal cycles) */
    wcsim_event_t *events;
    size_t n_events, cap_events, next_event;
    /* TX log */
    wcsim_tx_t *tx;
    size_t n_tx, cap_tx;
    /* hook log */
    uint32_t hook_pc[WCSIM_MAX_HOOKS];
    int n_hooks;
    uint8_t *hook_bits;   /* one bit per flash word: a hook starts there (one test per instruction) */
    /* interrupt entries: simavr 1.6 charges no cycle for the jump to a vector, the chip 5 */
    int charge_irq_entry;
    uint64_t irq_entries[64];     /* by vector number */
    /* cycle profile: cycles spent with the PC in [lo, hi) (byte addresses), per range */
    int n_prof;
    uint32_t prof_lo[16], prof_hi[16];
    uint64_t prof_cycles[16];
    uint32_t break_mask;  /* run_until stops before the hooks whose bit is set */
    int at_break;         /* stopped at a break: do not log the same entry twice */
    wcsim_hit_t *hits;
    size_t n_hits, cap_hits;
    /* VCD */
    avr_vcd_t vcd;
    int vcd_on;
    avr_irq_t *pwm_irq;   /* two 8-bit signals for the VCD: left, right duty */
    int crashed;
    /* resets */
    void (*run_fn)(avr_t *);    /* simavr's run callback; the WDT swaps in its reset */
    avr_watchdog_t *wdt;
    uint8_t driven[WCSIM_PORTS], level[WCSIM_PORTS];
    wcsim_reset_t *resets;
    size_t n_resets, cap_resets;
    /* the USART0 receiver */
    avr_uart_t *uart;
    wcsim_rx_t rx;
    uint64_t rx_index;           /* bytes that reached the receiver so far */
    wcsim_rx_lost_t *rx_lost;
    size_t n_rx_lost, cap_rx_lost;
    /* flow-controlled UART input (wcsim_feed, wcsim_run_fed): bytes wait here until the
     * USART's receive FIFO has room, as a USB-serial bridge holds them */
    uint8_t *feed;
    size_t n_feed, cap_feed, next_feed;
    avr_uart_t *uart0;
    avr_adc_t *adc;
} wcsim_t;

static void no_sleep(avr_t *avr, avr_cycle_count_t how_long) {
    (void)avr;
    (void)how_long;
}

/* simavr's own messages (ELF loading, register traces): only errors, to stderr. */
static void quiet_logger(avr_t *avr, const int level, const char *format, va_list ap) {
    (void)avr;
    if (level <= LOG_ERROR) vfprintf(stderr, format, ap);
}

static void *grow(void *p, size_t *cap, size_t need, size_t elem) {
    if (need <= *cap) return p;
    size_t c = *cap ? *cap : 256;
    while (c < need) c *= 2;
    void *q = realloc(p, c * elem);
    if (!q) return NULL;
    *cap = c;
    return q;
}

static void on_uart_tx(struct avr_irq_t *irq, uint32_t value, void *param) {
    (void)irq;
    wcsim_t *s = (wcsim_t *)param;
    wcsim_tx_t *t = grow(s->tx, &s->cap_tx, s->n_tx + 1, sizeof(*t));
    if (!t) return;
    s->tx = t;
    s->tx[s->n_tx].cycle = s->avr->cycle;
    s->tx[s->n_tx].byte = (uint8_t)value;
    s->n_tx++;
}

/* USART0 (simavr's module for it: its registers, RXC vector and DOR0 bit). */
static avr_uart_t *find_uart0(avr_t *avr) {
    for (avr_io_t *io = avr->io_port; io; io = io->next) {
        if (io->kind && strcmp(io->kind, "uart") == 0 && ((avr_uart_t *)io)->name == '0')
            return (avr_uart_t *)io;
    }
    return NULL;
}

/* UCSR0A and the RX interrupt as the FIFO's head makes them: RXC0 while the FIFO holds a
 * frame (the interrupt taken again after each read, as on the chip), DOR0 the head's. */
static void rx_update(wcsim_t *s) {
    avr_t *avr = s->avr;
    avr_uart_t *u = s->uart;
    wcsim_rx_t *r = &s->rx;
    if (r->n > 0 && r->dor[0]) avr_regbit_set(avr, u->dor);
    else avr_regbit_clear(avr, u->dor);
    if (r->n > 0) {
        if (!u->rxc.pending) avr_raise_interrupt(avr, &u->rxc);
    } else {
        avr_regbit_clear(avr, u->rxc.raised);
    }
}

static void log_rx_lost(wcsim_t *s, uint64_t index, uint8_t byte, uint8_t why) {
    wcsim_rx_lost_t *l = grow(s->rx_lost, &s->cap_rx_lost, s->n_rx_lost + 1, sizeof(*l));
    if (!l) return;
    s->rx_lost = l;
    l = &s->rx_lost[s->n_rx_lost++];
    l->cycle = s->avr->cycle;
    l->index = index;
    l->byte = byte;
    l->why = why;
}

/* A byte from the wire, its stop bit done now. With the receiver disabled it is lost. It
 * joins the FIFO, or waits in the shift register; when both are full the frame waiting
 * there is lost (data overrun) and this one takes its place, carrying DOR0: "one or more
 * serial frames were lost between the frame last read from UDRn and the next one". */
static void rx_arrive(wcsim_t *s, uint8_t byte) {
    uint64_t index = s->rx_index++;
    wcsim_rx_t *r = &s->rx;
    if (!s->uart || !avr_regbit_get(s->avr, s->uart->rxen)) {
        log_rx_lost(s, index, byte, 1);
        return;
    }
    if (r->n < 3) {
        r->data[r->n] = byte;
        r->dor[r->n] = 0;
        r->n++;
    } else {
        log_rx_lost(s, index - 1, r->data[2], 0);   /* the frame in the shift register */
        r->data[2] = byte;
        r->dor[2] = 1;
    }
    rx_update(s);
}

/* UDR0 read by the firmware: the FIFO's head; the shift register's frame moves up. */
static uint8_t rx_udr_read(avr_t *avr, avr_io_addr_t addr, void *param) {
    wcsim_t *s = (wcsim_t *)param;
    wcsim_rx_t *r = &s->rx;
    if (r->n > 0) {
        avr->data[addr] = r->data[0];
        r->data[0] = r->data[1];
        r->dor[0] = r->dor[1];
        r->data[1] = r->data[2];
        r->dor[1] = r->dor[2];
        r->n--;
    }
    rx_update(s);
    return avr->data[addr];
}

static uint8_t mcusr_get(wcsim_t *s) { return s->avr->data[s->avr->reset_flags.porf.reg]; }

static void log_reset(wcsim_t *s, int cause) {
    wcsim_reset_t *r = grow(s->resets, &s->cap_resets, s->n_resets + 1, sizeof(*r));
    if (!r) return;
    s->resets = r;
    r = &s->resets[s->n_resets++];
    r->cycle = s->avr->cycle;
    r->cause = (uint8_t)cause;
    r->mcusr = mcusr_get(s);
}

/* The watchdog module (for its WDE bit); simavr keeps it only in the core's struct. */
static avr_watchdog_t *find_watchdog(avr_t *avr) {
    for (avr_io_t *io = avr->io_port; io; io = io->next) {
        if (io->kind && strcmp(io->kind, "watchdog") == 0) return (avr_watchdog_t *)io;
    }
    return NULL;
}

/* A write to an I/O register as the core makes it (through the module's handler). */
static void io_write(avr_t *avr, avr_io_addr_t addr, uint8_t v) {
    avr_io_addr_t io = AVR_DATA_TO_IO(addr);
    if (avr->io[io].w.c)
        avr->io[io].w.c(avr, addr, v, avr->io[io].w.param);
    else
        avr->data[addr] = v;
}

/* The ADC module (for its read status); simavr keeps it only in the core's struct. */
static avr_adc_t *find_adc(avr_t *avr) {
    for (avr_io_t *io = avr->io_port; io; io = io->next) {
        if (io->kind && strcmp(io->kind, "adc") == 0) return (avr_adc_t *)io;
    }
    return NULL;
}

/* The ADC as a reset leaves the chip's: its data register (zeroed with the I/O
 * registers) reads 0 until a conversion completes. simavr 1.6 would sample the input
 * at the first ADCL read after a power-on, and keeps its read status across resets;
 * marked read, ADCL and ADCH give the register until the next conversion's end clears
 * the mark. The channels' millivolts are simavr's adc_values, which its reset leaves. */
static void adc_after_reset(wcsim_t *s) {
    if (s->adc) s->adc->read_status = 2;
}

/* The board's supply voltages: AVcc (the ADC's reference), AREF and Vcc, 5 V. Set once,
 * after the ELF is loaded (an ELF's .mmcu section may carry its own): avr_reset() leaves
 * them as they are. */
static void set_supply(wcsim_t *s) {
    s->avr->vcc = WCSIM_SUPPLY_MV;
    s->avr->avcc = WCSIM_SUPPLY_MV;
    s->avr->aref = WCSIM_SUPPLY_MV;
    s->adc = find_adc(s->avr);
    adc_after_reset(s);
}

/* After avr_reset() (which zeroes every I/O register, MCUSR and PINx included):
 *  - MCUSR as the hardware has it: a power-on leaves PORF alone; any other reset adds
 *    its flag to those the program has not cleared (simavr 1.6 sets only WDRF, on a
 *    watchdog reset, and clears the rest);
 *  - WDRF set forces WDE on (the watchdog runs at its shortest period), as on the chip;
 *  - the pins driven from outside show their levels again in PINx (their IRQs are
 *    filtered on value, so each is marked to notify once more, then raised);
 *  - a power-on also clears the register file and SRAM (defined: zero). */
static void after_reset(wcsim_t *s, int cause, uint8_t mcusr_before) {
    avr_t *avr = s->avr;
    uint8_t porf = 1u << avr->reset_flags.porf.bit;
    uint8_t extrf = 1u << avr->reset_flags.extrf.bit;
    uint8_t borf = 1u << avr->reset_flags.borf.bit;
    uint8_t wdrf = 1u << avr->reset_flags.wdrf.bit;
    uint8_t m;
    switch (cause) {
    case WCSIM_RESET_POWER_ON: m = porf; break;
    case WCSIM_RESET_EXTERNAL: m = mcusr_before | extrf; break;
    case WCSIM_RESET_BROWN_OUT: m = mcusr_before | borf; break;
    default: m = mcusr_before | wdrf; break;
    }
    avr->data[avr->reset_flags.porf.reg] = m;
    if (cause == WCSIM_RESET_POWER_ON) {
        memset(avr->data, 0, 32);
        memset(avr->data + avr->ioend + 1, 0, avr->ramend - avr->ioend);
    }
    if ((m & wdrf) && s->wdt && !avr_regbit_get(avr, s->wdt->wde)) {
        io_write(avr, s->wdt->wde.reg, (uint8_t)(1u << s->wdt->wde.bit));
    }
    for (int p = 0; p < WCSIM_PORTS; p++) {
        for (int b = 0; b < 8; b++) {
            avr_irq_t *irq = avr_io_getirq(avr, AVR_IOCTL_IOPORT_GETIRQ('A' + p), b);
            if (!irq) break;
            irq->flags |= IRQ_FLAG_INIT;
            if (s->driven[p] & (1u << b)) avr_raise_irq(irq, (s->level[p] >> b) & 1u);
        }
    }
    s->rx.n = 0;          /* the USART is reset with the chip: its FIFO is empty */
    if (s->uart) rx_update(s);
    adc_after_reset(s);
    s->at_break = 0;
    s->crashed = 0;
    log_reset(s, cause);
}

/* USART0's output comes to on_uart_tx, without simavr's stdio echo or poll sleep. */
static void listen_to_uart_tx(wcsim_t *s) {
    uint32_t flags = 0;
    avr_ioctl(s->avr, AVR_IOCTL_UART_GET_FLAGS('0'), &flags);
    flags &= ~(AVR_UART_FLAG_STDIO | AVR_UART_FLAG_POLL_SLEEP);
    avr_ioctl(s->avr, AVR_IOCTL_UART_SET_FLAGS('0'), &flags);
    avr_irq_register_notify(avr_io_getirq(s->avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_OUTPUT),
                            on_uart_tx, s);
}

wcsim_t *wcsim_new(const char *elf_path, char *err, int errlen) {
    wcsim_t *s = calloc(1, sizeof(*s));
    if (!s) return NULL;
    avr_global_logger_set(quiet_logger);
    if (elf_read_firmware(elf_path, &s->fw) != 0) {
        snprintf(err, errlen, "cannot read ELF %s", elf_path);
        free(s);
        return NULL;
    }
    const char *mmcu = s->fw.mmcu[0] ? s->fw.mmcu : "atmega2560";
    s->avr = avr_make_mcu_by_name(mmcu);
    if (!s->avr) {
        snprintf(err, errlen, "simavr knows no MCU %s", mmcu);
        free(s);
        return NULL;
    }
    avr_init(s->avr);
    s->avr->frequency = s->fw.frequency ? s->fw.frequency : 16000000;
    s->avr->log = 0;
    avr_load_firmware(s->avr, &s->fw);
    s->avr->sleep = no_sleep;
    set_supply(s);

    listen_to_uart_tx(s);
    /* The receiver is the harness's: UDR0 reads come here, not to simavr's 64-byte queue. */
    s->uart = find_uart0(s->avr);
    if (s->uart) {
        avr_io_addr_t io = AVR_DATA_TO_IO(s->uart->r_udr);
        s->avr->io[io].r.c = rx_udr_read;
        s->avr->io[io].r.param = s;
    }
    static const char *pwm_names[] = {"8>pwm_left", "8>pwm_right"};
    s->pwm_irq = avr_alloc_irq(&s->avr->irq_pool, 0, 2, pwm_names);
    s->run_fn = s->avr->run;
    s->wdt = find_watchdog(s->avr);
    s->charge_irq_entry = 1;
    log_reset(s, WCSIM_RESET_POWER_ON);   /* avr_init() reset the core and set PORF */
    return s;
}

void wcsim_free(wcsim_t *s) {
    if (!s) return;
    if (s->vcd_on) avr_vcd_close(&s->vcd);
    free(s->rx_lost);
    free(s->hook_bits);
    free(s->events);
    free(s->tx);
    free(s->hits);
    free(s->resets);
    free(s->feed);
    /* simavr 1.6 has no avr_free(); the MCU struct is reclaimed at exit. */
    free(s);
}

uint64_t wcsim_cycle(wcsim_t *s) { return s->avr->cycle; }
uint32_t wcsim_frequency(wcsim_t *s) { return s->avr->frequency; }
int wcsim_crashed(wcsim_t *s) { return s->crashed; }

/* Events must be queued in non-decreasing cycle order per call sequence; an
 * event earlier than one already queued is inserted in place. kind 0: pin (port, bit)
 * to level value; 1: the byte value reaches the USART; 2: ADC channel bit (0..7) at
 * value millivolts (0..65535). */
int wcsim_schedule(wcsim_t *s, uint64_t cycle, int kind, int port, int bit, int value) {
    wcsim_event_t *e = grow(s->events, &s->cap_events, s->n_events + 1, sizeof(*e));
    if (!e) return -1;
    s->events = e;
    size_t i = s->n_events;
    while (i > s->next_event && s->events[i - 1].cycle > cycle) {
        s->events[i] = s->events[i - 1];
        i--;
    }
    s->events[i].cycle = cycle;
    s->events[i].kind = (uint8_t)kind;
    s->events[i].port = (uint8_t)port;
    s->events[i].bit = (uint8_t)bit;
    s->events[i].value = (uint16_t)value;
    s->n_events++;
    return 0;
}

static void apply_event(wcsim_t *s, const wcsim_event_t *e) {
    if (e->kind == 0) {
        int p = e->port - 'A';
        if (p >= 0 && p < WCSIM_PORTS && e->bit < 8) {
            s->driven[p] |= (uint8_t)(1u << e->bit);
            s->level[p] = (uint8_t)((s->level[p] & ~(1u << e->bit)) | ((e->value ? 1u : 0u) << e->bit));
            /* Driven from outside, the pin keeps its level when the firmware writes the
             * port: simavr otherwise raises an input's internal pull-up again on every
             * PORTx write (an INPUT_PULLUP pin beside an output the sketch writes). */
            avr_ioport_external_t ext = { .name = e->port, .mask = s->driven[p], .value = s->level[p] };
            avr_ioctl(s->avr, AVR_IOCTL_IOPORT_SET_EXTERNAL(e->port), &ext);
        }
        avr_irq_t *irq = avr_io_getirq(s->avr, AVR_IOCTL_IOPORT_GETIRQ(e->port), e->bit);
        if (irq) avr_raise_irq(irq, e->value);
    } else if (e->kind == 2) {
        /* simavr's ADC keeps the channel's millivolts and converts them when the
         * firmware reads ADCL (avr_adc_read_l: mV * 0x3ff / AVcc, clipped to 0x3ff) */
        if (e->bit < WCSIM_ADC_CHANNELS) {
            avr_irq_t *irq = avr_io_getirq(s->avr, AVR_IOCTL_ADC_GETIRQ, ADC_IRQ_ADC0 + e->bit);
            if (irq) avr_raise_irq(irq, e->value);
        }
    } else {
        rx_arrive(s, (uint8_t)e->value);
    }
}

/* Queues n events at once, for encoder edge trains: the batch (sorted by cycle) is merged
 * with the pending queue in one pass, the queue's events first at equal cycles (as
 * one wcsim_schedule call after another would order them). Linear: a second encoder's
 * train no longer shifts the first one's events one insertion at a time. */
int wcsim_schedule_many(wcsim_t *s, size_t n, const uint64_t *cycles, const uint8_t *kinds,
                        const uint8_t *ports, const uint8_t *bits, const uint8_t *values) {
    if (n == 0) return 0;
    for (size_t i = 1; i < n; i++) {
        if (cycles[i] < cycles[i - 1]) return -2;
    }
    size_t pending = s->n_events - s->next_event;
    wcsim_event_t *merged = malloc((pending + n) * sizeof(*merged));
    if (!merged) return -1;
    size_t a = s->next_event, b = 0, k = 0;
    while (a < s->n_events || b < n) {
        if (b >= n || (a < s->n_events && s->events[a].cycle <= cycles[b])) {
            merged[k++] = s->events[a++];
        } else {
            merged[k].cycle = cycles[b];
            merged[k].kind = kinds[b];
            merged[k].port = ports[b];
            merged[k].bit = bits[b];
            merged[k].value = values[b];
            k++;
            b++;
        }
    }
    free(s->events);
    s->events = merged;
    s->cap_events = pending + n;
    s->n_events = pending + n;
    s->next_event = 0;
    return 0;
}

int wcsim_add_hook(wcsim_t *s, uint32_t pc_byte_addr) {
    if (s->n_hooks >= WCSIM_MAX_HOOKS) return -1;
    uint32_t words = (s->avr->flashend + 1) / 2;
    if (pc_byte_addr / 2 >= words) return -1;
    if (!s->hook_bits) {
        s->hook_bits = calloc(words / 8 + 1, 1);
        if (!s->hook_bits) return -1;
    }
    s->hook_bits[pc_byte_addr >> 4] |= (uint8_t)(1u << ((pc_byte_addr >> 1) & 7));
    s->hook_pc[s->n_hooks] = pc_byte_addr;
    return s->n_hooks++;
}

static void record_hit(wcsim_t *s, int h) {
    wcsim_hit_t *p = grow(s->hits, &s->cap_hits, s->n_hits + 1, sizeof(*p));
    if (!p) return;
    s->hits = p;
    uint8_t *r = s->avr->data;
    p = &s->hits[s->n_hits++];
    p->cycle = s->avr->cycle;
    p->hook = (uint32_t)h;
    p->arg = (uint32_t)r[22] | ((uint32_t)r[23] << 8) | ((uint32_t)r[24] << 16) | ((uint32_t)r[25] << 24);
    p->r24 = r[24];
}

void wcsim_set_break_mask(wcsim_t *s, uint32_t mask) { s->break_mask = mask; }

/* Resets the AVR now, the clock running on (see after_reset). cause: one of
 * WCSIM_RESET_POWER_ON, _EXTERNAL, _BROWN_OUT. Returns 0, or -1 for another cause.
 * It also revives a core that stopped (a real reset does). */
int wcsim_reset(wcsim_t *s, int cause) {
    if (cause != WCSIM_RESET_POWER_ON && cause != WCSIM_RESET_EXTERNAL && cause != WCSIM_RESET_BROWN_OUT)
        return -1;
    uint8_t before = mcusr_get(s);
    if (s->avr->run != s->run_fn && s->wdt) {
        /* A watchdog reset was due at this very instruction: take it back from simavr
         * (which would set WDRF and restart the WDT whatever the cause) and let
         * after_reset() set WDRF beside this cause's flag, unless it is a power-on. */
        s->avr->run = s->run_fn;
        s->wdt->reset_context.wdrf = 0;
        before |= (uint8_t)(1u << s->avr->reset_flags.wdrf.bit);
    }
    avr_reset(s->avr);
    after_reset(s, cause, before);
    return 0;
}

uint8_t wcsim_mcusr(wcsim_t *s) { return mcusr_get(s); }

size_t wcsim_resets_count(wcsim_t *s) { return s->n_resets; }

/* The log drains: each *_take copies up to max entries from the front of its log
 * and removes them. take_count is how many; drop_front removes them. */
static size_t take_count(size_t len, size_t max) { return len < max ? len : max; }

static void drop_front(void *log, size_t *len, size_t n, size_t size) {
    memmove(log, (char *)log + n * size, (*len - n) * size);
    *len -= n;
}

/* The body of a *_take: COPY copies entry i of log out, for the first n entries. */
#define DRAIN(log, count, max, COPY)                   \
    size_t n = take_count((count), (max));             \
    for (size_t i = 0; i < n; i++) { COPY; }           \
    drop_front((log), &(count), n, sizeof(*(log)));    \
    return n

/* Copies and removes up to max reset-log entries from the front of the log. */
size_t wcsim_resets_take(wcsim_t *s, uint64_t *cycles, uint8_t *causes, uint8_t *mcusr, size_t max) {
    DRAIN(s->resets, s->n_resets, max,
          (cycles[i] = s->resets[i].cycle,
           causes[i] = s->resets[i].cause,
           mcusr[i] = s->resets[i].mcusr));
}

/* Runs until avr->cycle >= target. Returns 0; 1 when it stopped at a break
 * hook (logged, not yet executed; the next call runs on past it); -1 when the
 * core stopped (crash or sleep with interrupts off).
 *
 * simavr 1.6's watchdog, when it expires in reset mode, swaps avr->run for a callback
 * that calls avr_reset() on the next avr_run() (no instruction runs in that call) and
 * sets WDRF and WDE (shortest period) from the watchdog's reset handler. The loop
 * sees the swap, lets that reset happen, then completes it (after_reset). */
int wcsim_run_until(wcsim_t *s, uint64_t target) {
    avr_t *avr = s->avr;
    while (avr->cycle < target) {
        while (s->next_event < s->n_events && s->events[s->next_event].cycle <= avr->cycle) {
            apply_event(s, &s->events[s->next_event]);
            s->next_event++;
        }
        if (s->next_event == s->n_events) {   /* drained: reuse the queue from the start */
            s->next_event = s->n_events = 0;
        }
        if (avr->run != s->run_fn) {          /* a watchdog reset is due */
            uint8_t before = mcusr_get(s);
            avr_run(avr);
            if (avr->run == s->run_fn) after_reset(s, WCSIM_RESET_WATCHDOG, before);
            else { s->crashed = 1; return -1; }   /* not simavr 1.6's watchdog: unknown state */
            continue;
        }
        uint32_t pc = avr->pc;
        if (s->hook_bits && (s->hook_bits[pc >> 4] & (1u << ((pc >> 1) & 7))))
        for (int h = 0; h < s->n_hooks; h++) {
            if (pc == s->hook_pc[h] && !s->at_break) {
                record_hit(s, h);
                if (s->break_mask & (1u << h)) {
                    s->at_break = 1;
                    return 1;
                }
            }
        }
        s->at_break = 0;
        uint64_t c0 = avr->cycle;
        int state = avr_run(avr);
        if (state == cpu_Done || state == cpu_Crashed) {
            s->crashed = 1;
            return -1;
        }
        uint32_t vectors_end = (uint32_t)avr->vector_size * 64u;
        if (avr->pc < vectors_end && pc >= vectors_end) {
            /* an interrupt was taken: the chip spends 5 cycles (PC pushed, I cleared)
             * before the vector's first instruction; simavr 1.6 none */
            unsigned v = avr->pc / avr->vector_size;
            if (v < 64) s->irq_entries[v]++;
            if (s->charge_irq_entry) avr->cycle += WCSIM_IRQ_ENTRY_CYCLES;
        }
        for (int r = 0; r < s->n_prof; r++) {
            if (pc >= s->prof_lo[r] && pc < s->prof_hi[r]) {
                s->prof_cycles[r] += avr->cycle - c0;
                break;
            }
        }
    }
    return 0;
}

/* Whether interrupt entries cost their 5 cycles (the default: as on the chip). */
void wcsim_charge_irq_entry(wcsim_t *s, int on) { s->charge_irq_entry = on; }

uint64_t wcsim_irq_entries(wcsim_t *s, int vector) {
    return vector >= 0 && vector < 64 ? s->irq_entries[vector] : 0;
}

/* The cycle profile: n ranges of byte addresses [lo, hi); an instruction's cycles (and an
 * interrupt entry's, charged to the instruction it followed) go to the first range that
 * holds its address. Setting the ranges clears the counts. */
int wcsim_prof_set(wcsim_t *s, int n, const uint32_t *lo, const uint32_t *hi) {
    if (n < 0 || n > 16) return -1;
    s->n_prof = n;
    for (int r = 0; r < n; r++) {
        s->prof_lo[r] = lo[r];
        s->prof_hi[r] = hi[r];
        s->prof_cycles[r] = 0;
    }
    return 0;
}

uint64_t wcsim_prof_get(wcsim_t *s, int r) { return r >= 0 && r < s->n_prof ? s->prof_cycles[r] : 0; }

size_t wcsim_tx_count(wcsim_t *s) { return s->n_tx; }

/* Bytes that reached the receiver so far, and those it holds (FIFO and shift register). */
uint64_t wcsim_rx_index(wcsim_t *s) { return s->rx_index; }
int wcsim_rx_held(wcsim_t *s) { return s->rx.n; }
size_t wcsim_rx_lost_count(wcsim_t *s) { return s->n_rx_lost; }

/* Copies and removes up to max entries from the front of the log of lost bytes. */
size_t wcsim_rx_lost_take(wcsim_t *s, uint64_t *cycles, uint64_t *indices, uint8_t *bytes,
                          uint8_t *why, size_t max) {
    DRAIN(s->rx_lost, s->n_rx_lost, max,
          (cycles[i] = s->rx_lost[i].cycle,
           indices[i] = s->rx_lost[i].index,
           bytes[i] = s->rx_lost[i].byte,
           why[i] = s->rx_lost[i].why));
}

/* Copies and removes up to max TX entries from the front of the log. */
size_t wcsim_tx_take(wcsim_t *s, uint64_t *cycles, uint8_t *bytes, size_t max) {
    DRAIN(s->tx, s->n_tx, max,
          (cycles[i] = s->tx[i].cycle,
           bytes[i] = s->tx[i].byte));
}

size_t wcsim_hits_count(wcsim_t *s) { return s->n_hits; }

size_t wcsim_hits_take(wcsim_t *s, uint64_t *cycles, uint32_t *hooks, uint32_t *args, size_t max) {
    DRAIN(s->hits, s->n_hits, max,
          (cycles[i] = s->hits[i].cycle,
           hooks[i] = s->hits[i].hook,
           args[i] = s->hits[i].arg));
}

/* Data space: registers, I/O, SRAM (addresses as avr-nm prints them less 0x800000). */
int wcsim_read(wcsim_t *s, uint32_t addr, uint8_t *buf, uint32_t n) {
    if ((uint64_t)addr + n > (uint64_t)s->avr->ramend + 1) return -1;
    memcpy(buf, s->avr->data + addr, n);
    return 0;
}

int wcsim_write(wcsim_t *s, uint32_t addr, const uint8_t *buf, uint32_t n) {
    if ((uint64_t)addr + n > (uint64_t)s->avr->ramend + 1) return -1;
    memcpy(s->avr->data + addr, buf, n);
    return 0;
}

uint32_t wcsim_ramend(wcsim_t *s) { return s->avr->ramend; }

/* The EEPROM (simavr's avr_eeprom: erased to 0xFF when the core is made; avr_reset()
 * leaves it as it is, as a reset leaves the chip's). AVR_IOCTL_EEPROM_GET with no buffer
 * gives simavr's own array; its SET/GET refuse a range that ends at the last byte and
 * print, so the harness copies itself. Returns the size, or 0 when the core has none. */
static uint8_t *eeprom_array(wcsim_t *s) {
    avr_eeprom_desc_t d = { .ee = NULL, .offset = 0, .size = 0 };
    if (avr_ioctl(s->avr, AVR_IOCTL_EEPROM_GET, &d) < -1) return NULL;
    return d.ee;
}

uint32_t wcsim_eeprom_size(wcsim_t *s) { return eeprom_array(s) ? s->avr->e2end + 1 : 0; }

int wcsim_eeprom_read(wcsim_t *s, uint32_t addr, uint8_t *buf, uint32_t n) {
    uint8_t *ee = eeprom_array(s);
    if (!ee || (uint64_t)addr + n > (uint64_t)s->avr->e2end + 1) return -1;
    memcpy(buf, ee + addr, n);
    return 0;
}

int wcsim_eeprom_write(wcsim_t *s, uint32_t addr, const uint8_t *buf, uint32_t n) {
    uint8_t *ee = eeprom_array(s);
    if (!ee || (uint64_t)addr + n > (uint64_t)s->avr->e2end + 1) return -1;
    memcpy(ee + addr, buf, n);
    return 0;
}

/* Stack pointer, for free-RAM measurements. */
uint32_t wcsim_sp(wcsim_t *s) { return (uint32_t)s->avr->data[0x5d] | ((uint32_t)s->avr->data[0x5e] << 8); }

/* Feeds the two PWM duty values into the VCD (called by Python when it samples). */
void wcsim_vcd_pwm(wcsim_t *s, int left, int right) {
    avr_raise_irq(s->pwm_irq + 0, (uint32_t)left);
    avr_raise_irq(s->pwm_irq + 1, (uint32_t)right);
}

/* VCD of the given port pins plus UART RX/TX bytes and the PWM duty signals.
 * pins: a string of "<port><bit>:<name>;" entries, e.g. "E4:enc_l_a;E5:enc_l_b;". */
int wcsim_vcd_open(wcsim_t *s, const char *path, const char *pins) {
    if (s->vcd_on) return -1;
    if (avr_vcd_init(s->avr, path, &s->vcd, 1000) != 0) return -1;
    char buf[512];
    snprintf(buf, sizeof(buf), "%s", pins);
    for (char *tok = strtok(buf, ";"); tok; tok = strtok(NULL, ";")) {
        if (strlen(tok) < 4 || tok[2] != ':') continue;
        avr_irq_t *irq = avr_io_getirq(s->avr, AVR_IOCTL_IOPORT_GETIRQ(tok[0]), tok[1] - '0');
        if (irq) avr_vcd_add_signal(&s->vcd, irq, 1, strdup(tok + 3));
    }
    avr_vcd_add_signal(&s->vcd, avr_io_getirq(s->avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_INPUT), 8,
                       "uart_rx");
    avr_vcd_add_signal(&s->vcd, avr_io_getirq(s->avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_OUTPUT), 8,
                       "uart_tx");
    avr_vcd_add_signal(&s->vcd, s->pwm_irq + 0, 8, "pwm_left");
    avr_vcd_add_signal(&s->vcd, s->pwm_irq + 1, 8, "pwm_right");
    avr_vcd_start(&s->vcd);
    s->vcd_on = 1;
    return 0;
}

void wcsim_vcd_close(wcsim_t *s) {
    if (!s->vcd_on) return;
    avr_vcd_stop(&s->vcd);
    avr_vcd_close(&s->vcd);
    s->vcd_on = 0;
}

/* ---- a bare chip: flash loaded from Python, a bootloader, flow-controlled UART input ---- */

/* INT0..7 at their reset value (ISC 00, low level) with a pin held low make simavr
 * 1.6 poll that pin every cycle even while the interrupt is disabled: the bootloader's
 * case after a reset with an encoder line low, about 5x slower (measured). Off, a
 * level interrupt fires once when the level comes, not again while it lasts; neither
 * the bootloader nor final_control (CHANGE interrupts) uses level interrupts. simavr
 * turns it back on at every reset, so wcsim_run_fed checks it. */
static void chip_lax_level_trigger(wcsim_t *s) {
    for (uint8_t i = 0; i < 8; i++) avr_extint_set_strict_lvl_trig(s->avr, i, 0);
}

/* A chip with erased flash (0xFF) and no ELF: wcsim_flash_write loads it, wcsim_set_reset_pc
 * moves the reset vector (BOOTRST). Otherwise as wcsim_new. */
wcsim_t *wcsim_new_chip(const char *mmcu, uint32_t frequency, char *err, int errlen) {
    wcsim_t *s = calloc(1, sizeof(*s));
    if (!s) return NULL;
    avr_global_logger_set(quiet_logger);
    s->avr = avr_make_mcu_by_name(mmcu);
    if (!s->avr) {
        snprintf(err, errlen, "simavr knows no MCU %s", mmcu);
        free(s);
        return NULL;
    }
    avr_init(s->avr);
    s->avr->frequency = frequency;
    s->avr->log = 0;
    memset(s->avr->flash, 0xFF, s->avr->flashend + 1);
    s->avr->codeend = s->avr->flashend;
    s->avr->sleep = no_sleep;
    set_supply(s);
    listen_to_uart_tx(s);
    static const char *pwm_names[] = {"8>pwm_left", "8>pwm_right"};
    s->pwm_irq = avr_alloc_irq(&s->avr->irq_pool, 0, 2, pwm_names);
    s->run_fn = s->avr->run;
    s->wdt = find_watchdog(s->avr);
    s->uart0 = find_uart0(s->avr);
    s->charge_irq_entry = 1;
    chip_lax_level_trigger(s);
    log_reset(s, WCSIM_RESET_POWER_ON);
    return s;
}

uint32_t wcsim_flash_size(wcsim_t *s) { return s->avr->flashend + 1; }

int wcsim_flash_write(wcsim_t *s, uint32_t addr, const uint8_t *buf, uint32_t n) {
    if ((uint64_t)addr + n > (uint64_t)s->avr->flashend + 1) return -1;
    memcpy(s->avr->flash + addr, buf, n);
    return 0;
}

int wcsim_flash_read(wcsim_t *s, uint32_t addr, uint8_t *buf, uint32_t n) {
    if ((uint64_t)addr + n > (uint64_t)s->avr->flashend + 1) return -1;
    memcpy(buf, s->avr->flash + addr, n);
    return 0;
}

/* The reset vector (a byte address): BOOTRST programmed moves it to the boot section.
 * Takes effect now when the core is still at the old vector, else at the next reset. */
void wcsim_set_reset_pc(wcsim_t *s, uint32_t pc) {
    if (s->avr->pc == s->avr->reset_pc) s->avr->pc = pc;
    s->avr->reset_pc = pc;
}

uint32_t wcsim_pc(wcsim_t *s) { return s->avr->pc; }

/* Bytes for the USART0 receiver, held until its FIFO has room (the XON side of
 * simavr's UART): none is lost to an overrun; bytes that reach a disabled receiver
 * are lost, as on the chip. */
int wcsim_feed(wcsim_t *s, const uint8_t *buf, size_t n) {
    if (s->next_feed == s->n_feed) s->next_feed = s->n_feed = 0;
    uint8_t *f = grow(s->feed, &s->cap_feed, s->n_feed + n, 1);
    if (!f) return -1;
    s->feed = f;
    memcpy(s->feed + s->n_feed, buf, n);
    s->n_feed += n;
    return 0;
}

size_t wcsim_feed_pending(wcsim_t *s) { return s->n_feed - s->next_feed; }

void wcsim_feed_clear(wcsim_t *s) { s->next_feed = s->n_feed = 0; }

static void feed_uart(wcsim_t *s) {
    avr_irq_t *in = avr_io_getirq(s->avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_INPUT);
    while (s->next_feed < s->n_feed) {
        if (s->uart0 && ((s->uart0->input.write + 1) & (uart_fifo_fifo_size - 1)) == s->uart0->input.read) break;
        avr_raise_irq(in, s->feed[s->next_feed++]);
    }
}

/* wcsim_run_until, with the held bytes fed to the USART whenever its FIFO has room
 * (checked every 64 cycles, well under a byte time). */
int wcsim_run_fed(wcsim_t *s, uint64_t target) {
    while (s->avr->cycle < target) {
        if (avr_extint_is_strict_lvl_trig(s->avr, 4)) chip_lax_level_trigger(s);
        feed_uart(s);
        uint64_t step = s->avr->cycle + 64;
        int r = wcsim_run_until(s, step < target ? step : target);
        if (r != 0) return r;
    }
    return 0;
}
