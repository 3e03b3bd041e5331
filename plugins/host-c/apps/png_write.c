/* PNG: signature, IHDR, one IDAT of the filtered rows (filter 0: none, the pictures are small
 * enough that better filters buy little), IEND; each chunk with its CRC (zlib's crc32). */
#include "png_write.h"

#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <zlib.h>

static void be32(uint8_t *p, uint32_t v) {
    p[0] = (uint8_t)(v >> 24);
    p[1] = (uint8_t)(v >> 16);
    p[2] = (uint8_t)(v >> 8);
    p[3] = (uint8_t)v;
}

static int chunk(FILE *f, const char *type, const uint8_t *data, uint32_t len) {
    uint8_t head[8], tail[4];
    uLong crc = crc32(0L, (const Bytef *)type, 4);
    if (len)
        crc = crc32(crc, data, len);
    be32(head, len);
    memcpy(head + 4, type, 4);
    be32(tail, (uint32_t)crc);
    return fwrite(head, 1, 8, f) == 8 && (len == 0 || fwrite(data, 1, len, f) == len) &&
           fwrite(tail, 1, 4, f) == 4;
}

int png_write_rgba(const char *path, const uint8_t *rgba, uint32_t width, uint32_t height,
                   char *err, size_t err_size) {
    static const uint8_t signature[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
    uint8_t ihdr[13];
    size_t row = (size_t)width * 4, raw_len, i;
    uint8_t *raw = NULL, *packed = NULL;
    uLongf packed_len;
    FILE *f = NULL;
    int ok = 0;
    const char *why = "out of memory";

    if (!path || !rgba || width == 0 || height == 0 || width > 65535 || height > 65535) {
        why = "no picture to write";
        goto done;
    }
    raw_len = (row + 1) * height;
    raw = malloc(raw_len);
    packed_len = compressBound((uLong)raw_len);
    packed = malloc(packed_len);
    if (!raw || !packed)
        goto done;
    for (i = 0; i < height; ++i) {
        raw[i * (row + 1)] = 0;
        memcpy(raw + i * (row + 1) + 1, rgba + i * row, row);
    }
    if (compress2(packed, &packed_len, raw, (uLong)raw_len, 6) != Z_OK) {
        why = "zlib could not deflate the rows";
        goto done;
    }
    be32(ihdr, width);
    be32(ihdr + 4, height);
    ihdr[8] = 8;  /* bit depth */
    ihdr[9] = 6;  /* RGBA */
    ihdr[10] = 0; /* deflate */
    ihdr[11] = 0; /* adaptive filtering */
    ihdr[12] = 0; /* no interlace */
    f = fopen(path, "wb");
    if (!f) {
        why = strerror(errno);
        goto done;
    }
    ok = fwrite(signature, 1, 8, f) == 8 && chunk(f, "IHDR", ihdr, 13) &&
         chunk(f, "IDAT", packed, (uint32_t)packed_len) && chunk(f, "IEND", NULL, 0);
    if (fclose(f) != 0)
        ok = 0;
    f = NULL;
    if (!ok)
        why = strerror(errno ? errno : EIO);
done:
    if (f)
        fclose(f);
    free(raw);
    free(packed);
    if (!ok && err && err_size)
        snprintf(err, err_size, "%s: %s", path ? path : "(null)", why);
    return ok ? 0 : -1;
}

static void le32f(uint8_t *p, float v) {
    uint32_t bits;
    memcpy(&bits, &v, sizeof bits);
    p[0] = (uint8_t)bits;
    p[1] = (uint8_t)(bits >> 8);
    p[2] = (uint8_t)(bits >> 16);
    p[3] = (uint8_t)(bits >> 24);
}

int pfm_write_rgb(const char *path, const float *rgba, uint32_t width, uint32_t height,
                  char *err, size_t err_size) {
    FILE *f = fopen(path, "wb");
    uint8_t *row = malloc((size_t)width * 12 + 1);
    int good;
    if (!f || !row) {
        if (err_size)
            snprintf(err, err_size, "cannot write %s: %s", path, f ? "out of memory" : strerror(errno));
        if (f)
            fclose(f);
        free(row);
        return -1;
    }
    good = fprintf(f, "PF\n%u %u\n-1.0\n", (unsigned)width, (unsigned)height) > 0;
    for (uint32_t y = height; good && y-- > 0;) { /* the format's rows go bottom first */
        const float *src = rgba + (size_t)y * width * 4;
        for (uint32_t x = 0; x < width; ++x)
            for (int c = 0; c < 3; ++c)
                le32f(row + (size_t)x * 12 + (size_t)c * 4, src[(size_t)x * 4 + (size_t)c]);
        good = fwrite(row, 12, width, f) == width;
    }
    free(row);
    if (fclose(f) != 0)
        good = 0;
    if (!good) {
        if (err_size)
            snprintf(err, err_size, "cannot write %s: %s", path, strerror(errno));
        return -1;
    }
    return 0;
}
