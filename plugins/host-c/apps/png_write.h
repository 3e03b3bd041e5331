/* A PNG writer for the host kit's programs (wxsky-host-snapshot, wxsky-host-demo): 8-bit RGBA,
 * top row first, deflated with zlib. Not part of the library: a simulator has its own image
 * code, these programs only need to leave a picture a person can open. */
#ifndef WXSKY_APPS_PNG_WRITE_H
#define WXSKY_APPS_PNG_WRITE_H

#include <stddef.h>
#include <stdint.h>

/* Writes width x height RGBA8 pixels (rows of width * 4 bytes, top first) to path.
 * 0 on success; -1 with a one-line reason in err (err_size bytes, may be 0) otherwise. */
int png_write_rgba(const char *path, const uint8_t *rgba, uint32_t width, uint32_t height,
                   char *err, size_t err_size);

/* Writes the RGB of width x height float RGBA pixels (rows top first) as a colour Portable
 * Float Map: "PF", the size, scale -1.0 (little-endian), float32 RGB rows bottom first, as
 * `wxsky snapshot --linear-out` writes them. 0, or -1 with a one-line reason in err. */
int pfm_write_rgb(const char *path, const float *rgba, uint32_t width, uint32_t height,
                  char *err, size_t err_size);

#endif
