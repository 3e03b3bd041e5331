/* Status names, the library version, and the one helper that writes an object's message. */
#include "internal.h"

#include <stdarg.h>
#include <stdio.h>

uint32_t wxsky_host_version(void) {
    return ((uint32_t)WXSKY_HOST_VERSION_MAJOR << 16) | (uint32_t)WXSKY_HOST_VERSION_MINOR;
}

const char *wxsky_status_name(int status) {
    switch (status) {
    case WXSKY_OK: return "WXSKY_OK";
    case WXSKY_AGAIN: return "WXSKY_AGAIN";
    case WXSKY_STARTING: return "WXSKY_STARTING";
    case WXSKY_EINVAL: return "WXSKY_EINVAL";
    case WXSKY_ENOENT: return "WXSKY_ENOENT";
    case WXSKY_EFORMAT: return "WXSKY_EFORMAT";
    case WXSKY_EVERSION: return "WXSKY_EVERSION";
    case WXSKY_ETORN: return "WXSKY_ETORN";
    case WXSKY_ECLOSED: return "WXSKY_ECLOSED";
    case WXSKY_ESYS: return "WXSKY_ESYS";
    case WXSKY_ENOSPC: return "WXSKY_ENOSPC";
    case WXSKY_ETIMEDOUT: return "WXSKY_ETIMEDOUT";
    case WXSKY_EREMOTE: return "WXSKY_EREMOTE";
    default: return "unknown";
    }
}

int wxsky_fail(char *error, size_t size, int status, const char *fmt, ...) {
    if (error != NULL && size > 0) {
        va_list ap;
        va_start(ap, fmt);
        vsnprintf(error, size, fmt, ap);
        va_end(ap);
    }
    return status;
}
