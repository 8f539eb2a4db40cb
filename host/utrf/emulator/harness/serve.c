/* UART0 served to client processes: a pty and a TCP listener on the loopback interface.
 *
 * Everything is non-blocking and polled from the simulation loop, so bytes move between
 * the host and the board only at lockstep boundaries. A pty has a client while its slave
 * side is open (the master sees POLLHUP otherwise); output while nobody listens is lost, as
 * on a serial line. With auto-reset, a new client resets the board, as the MEGA's USB-serial
 * chip does when a port is opened (DTR).
 *
 * DTR, as Linux drives it for a real serial port: opening the port raises DTR (the MEGA resets
 * on that edge), and the last close drops it only if HUPCL is set in the port's termios (the
 * default). A client that clears HUPCL leaves DTR raised when it closes, so the next open is
 * no edge and does not reset the board (`Hand.connect(url, reset=False)`). The pty models
 * exactly that: the slave's termios (which the master reads) is checked while nobody has it
 * open. A TCP connection has no DTR line: every connection is an open that raises it.
 *
 * One host at a time, as on a serial port: while a host is attached (on the pty or on TCP),
 * a second one is turned away with one text line, `utrf busy: ...` (the host's Link reports it:
 * protocol/README.md), and hears nothing of the board; a TCP one is then hung up on.
 */
#define _GNU_SOURCE
#include <errno.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <arpa/inet.h>
#include <poll.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <termios.h>
#include <unistd.h>

#include "harness_internal.h"

void serve_init(utrf_sim_t *s)
{
    s->pty_fd = -1;
    s->listen_fd = -1;
    s->client_fd = -1;
    s->pty_open = 0;
    s->pty_dtr = 0;
    s->pty_refused = 0;
}

/* The pty's opener is the board's host (not one turned away). */
static int pty_host(const utrf_sim_t *s)
{
    return s->pty_open && !s->pty_refused;
}

static void refuse(int fd, const char *holder)
{
    char line[160];
    int n = snprintf(line, sizeof line,
                     "utrf busy: the emulator already has a host attached (%s); one host at a time\n",
                     holder);
    if (n > 0 && write(fd, line, (size_t)n) < 0) {
        /* nothing more to do for a host that is turned away */
    }
}

static void client_connected(utrf_sim_t *s, int dtr_edge)
{
    s->stats.clients++;
    /* A new session: the previous client's unsent bytes are not this one's. */
    s->rx_tail = s->rx_head;
    if (s->auto_reset && dtr_edge)
        utrf_sim_reset(s, UTRF_SIM_RESET_PIN, s->auto_reset_hold);
}

static void close_client(utrf_sim_t *s)
{
    if (s->client_fd >= 0)
        close(s->client_fd);
    s->client_fd = -1;
}

int utrf_sim_serve_pty(utrf_sim_t *s, char *path, size_t len)
{
    if (s->pty_fd >= 0) {
        snprintf(path, len, "%s", s->pty_path);
        return 0;
    }
    int m = posix_openpt(O_RDWR | O_NOCTTY | O_NONBLOCK);
    if (m < 0)
        return -errno;
    if (grantpt(m) || unlockpt(m) || ptsname_r(m, s->pty_path, sizeof s->pty_path)) {
        int e = errno;
        close(m);
        return -e;
    }
    fcntl(m, F_SETFD, FD_CLOEXEC);
    /* Raw mode, set once on the slave side; it stays for every later opener. */
    int sl = open(s->pty_path, O_RDWR | O_NOCTTY | O_CLOEXEC);
    if (sl >= 0) {
        struct termios t;
        if (tcgetattr(sl, &t) == 0) {
            cfmakeraw(&t);
            t.c_cflag |= HUPCL; /* a serial port's default (a pty's is off) */
            tcsetattr(sl, TCSANOW, &t);
        }
        close(sl);
    }
    s->pty_fd = m;
    s->pty_open = 0;
    s->pty_dtr = 0;
    snprintf(path, len, "%s", s->pty_path);
    return 0;
}

int utrf_sim_serve_tcp(utrf_sim_t *s, const char *host, int port)
{
    if (s->listen_fd >= 0)
        return -EALREADY;
    if (port < 0 || port > 65535)
        return -EINVAL;
    struct sockaddr_in addr = {.sin_family = AF_INET, .sin_port = htons((uint16_t)port)};
    if (inet_pton(AF_INET, host, &addr.sin_addr) != 1)
        return -EINVAL;
    int fd = socket(AF_INET, SOCK_STREAM | SOCK_NONBLOCK | SOCK_CLOEXEC, 0);
    if (fd < 0)
        return -errno;
    int one = 1;
    setsockopt(fd, SOL_SOCKET, SO_REUSEADDR, &one, sizeof one);
    if (bind(fd, (struct sockaddr *)&addr, sizeof addr) || listen(fd, 4)) {
        int e = errno;
        close(fd);
        return -e;
    }
    socklen_t alen = sizeof addr;
    getsockname(fd, (struct sockaddr *)&addr, &alen);
    s->listen_fd = fd;
    return ntohs(addr.sin_port);
}

void utrf_sim_set_auto_reset(utrf_sim_t *s, int on)
{
    s->auto_reset = on != 0;
}

void utrf_sim_drop_client(utrf_sim_t *s)
{
    close_client(s);
}

int utrf_sim_clients(const utrf_sim_t *s)
{
    return (pty_host(s) ? 1 : 0) | (s->client_fd >= 0 ? 2 : 0);
}

static void read_into_queue(utrf_sim_t *s, int fd, int is_socket)
{
    uint8_t buf[4096];
    for (;;) {
        size_t space = bridge_rx_space(s);
        if (!space)
            return; /* back-pressure: the rest stays in the kernel's buffer */
        if (space > sizeof buf)
            space = sizeof buf;
        ssize_t n = read(fd, buf, space);
        if (n > 0) {
            utrf_sim_uart_write(s, buf, (size_t)n);
            continue;
        }
        if (is_socket && (n == 0 || (errno != EAGAIN && errno != EINTR)))
            close_client(s);
        return;
    }
}

void serve_poll(utrf_sim_t *s, int timeout_ms)
{
    struct pollfd p[3];
    int n = 0, ipty = -1, ilisten = -1, iclient = -1;
    if (s->pty_fd >= 0)
        ipty = n, p[n++] = (struct pollfd){s->pty_fd, POLLIN, 0};
    if (s->listen_fd >= 0)
        ilisten = n, p[n++] = (struct pollfd){s->listen_fd, POLLIN, 0};
    if (s->client_fd >= 0)
        iclient = n, p[n++] = (struct pollfd){s->client_fd, POLLIN, 0};
    /* No event on the pty is news too: its slave side is open (POLLHUP otherwise). */
    if (!n || poll(p, (nfds_t)n, timeout_ms) < 0)
        return;

    if (ipty >= 0) {
        int open_now = !(p[ipty].revents & POLLHUP);
        if (open_now && !s->pty_open) {
            s->pty_open = 1;
            tcflush(s->pty_fd, TCIOFLUSH);
            if (s->client_fd >= 0) {
                s->pty_refused = 1; /* until it closes: the TCP host keeps the board */
                refuse(s->pty_fd, "a TCP client, on its socket");
            } else {
                client_connected(s, !s->pty_dtr);
                s->pty_dtr = 1;
            }
        } else if (!open_now) {
            s->pty_open = 0;
            s->pty_refused = 0;
            /* Closed (or opened and closed between two polls): HUPCL set means DTR dropped. */
            struct termios t;
            if (tcgetattr(s->pty_fd, &t) == 0 && (t.c_cflag & HUPCL))
                s->pty_dtr = 0;
        }
        if (open_now && (p[ipty].revents & POLLIN)) {
            if (s->pty_refused)
                tcflush(s->pty_fd, TCIFLUSH); /* a host turned away is not heard */
            else
                read_into_queue(s, s->pty_fd, 0);
        }
    }
    if (ilisten >= 0 && (p[ilisten].revents & POLLIN)) {
        int fd = accept4(s->listen_fd, NULL, NULL, SOCK_NONBLOCK | SOCK_CLOEXEC);
        if (fd >= 0) {
            if (s->client_fd >= 0 || pty_host(s)) {
                /* one host at a time, like a serial port */
                refuse(fd, s->client_fd >= 0 ? "a TCP client, on its socket" : s->pty_path);
                shutdown(fd, SHUT_WR);
                close(fd);
            } else {
                int one = 1;
                setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
                s->client_fd = fd;
                client_connected(s, 1);
                iclient = -1; /* not in this poll set */
            }
        }
    }
    if (iclient >= 0 && s->client_fd >= 0 && (p[iclient].revents & (POLLIN | POLLHUP | POLLERR)))
        read_into_queue(s, s->client_fd, 1);
}

void serve_write(utrf_sim_t *s, const uint8_t *buf, size_t n)
{
    /* A byte is heard when at least one sink takes it. */
    size_t taken = s->capture_on ? n : 0;
    if (s->pty_fd >= 0 && pty_host(s)) {
        ssize_t w = write(s->pty_fd, buf, n);
        if (w > 0 && (size_t)w > taken)
            taken = (size_t)w;
    }
    if (s->client_fd >= 0) {
        ssize_t w = send(s->client_fd, buf, n, MSG_NOSIGNAL | MSG_DONTWAIT);
        if (w < 0 && errno != EAGAIN && errno != EINTR)
            close_client(s);
        else if (w > 0 && (size_t)w > taken)
            taken = (size_t)w;
    }
    s->stats.tx_unheard += n - taken;
}

void serve_close(utrf_sim_t *s)
{
    close_client(s);
    if (s->listen_fd >= 0)
        close(s->listen_fd);
    if (s->pty_fd >= 0)
        close(s->pty_fd);
    s->listen_fd = s->pty_fd = -1;
    s->pty_open = 0;
    s->pty_refused = 0;
}
