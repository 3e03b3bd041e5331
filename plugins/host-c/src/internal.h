/* Shared by the kit's sources; not installed. */
#ifndef WXSKY_HOST_INTERNAL_H
#define WXSKY_HOST_INTERNAL_H

#include "wxsky_host.h"

#if defined(__GNUC__)
#define WXSKY_PRINTF(f, a) __attribute__((format(printf, f, a)))
#else
#define WXSKY_PRINTF(f, a)
#endif

/* The seqlock needs acquire loads and fences (protocol §1.4); C99 has no <stdatomic.h>, so
 * the GCC/Clang builtins, which every compiler a simulator is built with here provides. */
#define WXSKY_LOAD_ACQUIRE(p) __atomic_load_n((p), __ATOMIC_ACQUIRE)
#define WXSKY_LOAD_RELAXED(p) __atomic_load_n((p), __ATOMIC_RELAXED)
#define WXSKY_FENCE_ACQUIRE() __atomic_thread_fence(__ATOMIC_ACQUIRE)

/* Writes a one-line message into error[size] (if not NULL) and returns status. */
int wxsky_fail(char *error, size_t size, int status, const char *fmt, ...) WXSKY_PRINTF(4, 5);

/* wxsky_client_call, then the descriptors that came with the response (SCM_RIGHTS, §6),
 * at most max_fds of them, handed to the caller (who closes them). *fd_count is 0 when the
 * response came from the queue (it arrived during an earlier wait, and its descriptors were
 * closed with the bytes they came with). */
int wxsky_client_call_fds(wxsky_client *c, const char *method, const uint8_t *params_msgpack,
                          size_t params_len, int timeout_ms, wxsky_message *response,
                          int *fds, size_t max_fds, size_t *fd_count);
/* Leaves a message in the client (wxsky_client_error) and returns status. */
int wxsky_client_fail(wxsky_client *c, int status, const char *fmt, ...) WXSKY_PRINTF(3, 4);
/* Descriptors closed on arrival: more than the client holds, or cut by the kernel. */
uint64_t wxsky_client_fds_lost(const wxsky_client *c);

#endif
