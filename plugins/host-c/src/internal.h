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

#endif
