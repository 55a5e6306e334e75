/*
 * libFuzzer target for the C reader (include/nelf.h): whole-file and random-access
 * reads of arbitrary bytes, then every accessor, reconstruction and relighting on
 * whatever was accepted. Build and run with include/fuzz/run.sh:
 *
 *   clang -std=c99 -g -O1 -fsanitize=fuzzer,address,undefined -fno-sanitize-recover=all \
 *         -I include include/fuzz/fuzz_nelf.c -o fuzz_nelf -lzstd -lxxhash -lm
 *
 * Checksum mismatches are ignored (NELF_FUZZING_IGNORE_CHECKSUMS) so that mutated
 * inputs reach the decoders and value checks behind the checksums; define
 * NELF_FUZZ_WITH_CHECKSUMS to fuzz the reader exactly as shipped.
 */
#ifndef NELF_FUZZ_WITH_CHECKSUMS
#define NELF_FUZZING_IGNORE_CHECKSUMS
#endif
#define NELF_IMPLEMENTATION
#include "nelf.h"

#include <stdint.h>
#include <stdlib.h>
#include <string.h>

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

/* Uses every value it is given, so that reads of uninitialised or freed memory and
 * non-finite arithmetic on accepted files are reached. */
static volatile float g_sink;

static void exercise(nelf_reader *r) {
    static nelf_projected_light light;
    float map[NELF_ENV_TEXELS * 3], lt[NELF_LT_DIM], rgb[3];
    const nelf_header *h = nelf_get_header(r);
    const uint16_t *coords = nelf_brick_coords(r);
    size_t meta_length = 0, i;
    const char *meta = nelf_metadata(r, &meta_length);
    uint32_t b, s, n;
    for (i = 0; i < meta_length; i++) g_sink += (float)meta[i];
    for (s = 0; s < nelf_section_count(r); s++) g_sink += (float)nelf_get_section(r, s)->raw_length;
    for (i = 0; i < NELF_ENV_TEXELS * 3; i++) map[i] = (float)(i % 5) - 1.0f;
    if (nelf_project_light(r, map, &light) != NELF_OK) abort();
    if (nelf_get_reflection(r)) {
        const nelf_reflection *part = nelf_get_reflection(r);
        if (part->eye_count < 1 || part->eye_count > NELF_MAX_REFLECTION_EYES) abort();
        g_sink += part->exponent + part->eyes_m[part->eye_count - 1][2] + part->offset[2];
    }
    /* Random access: the last brick, the first, then up to 64 in order. */
    n = h->brick_count < 64 ? h->brick_count : 64;
    for (b = 0; b < n + 2 && h->brick_count > 0; b++) {
        uint32_t index = b == 0 ? h->brick_count - 1 : b == 1 ? 0 : b - 2;
        nelf_brick brick;
        double centre[3];
        if (nelf_read_brick(r, index, &brick) != NELF_OK) break;
        if (nelf_find_brick(r, coords[3 * index], coords[3 * index + 1], coords[3 * index + 2]) != (int64_t)index) abort();
        for (i = 0; i < NELF_BRICK_VOXELS; i += 73) {
            const float *c = brick.coefficients + i * h->pca_rank;
            nelf_reconstruct(r, c, h->pca_rank, lt);
            nelf_relight(&light, c, h->pca_rank, rgb);
            nelf_shade(lt, map, rgb);
            g_sink += brick.density[i] + rgb[0] + lt[NELF_LT_DIM - 1];
            if (nelf_voxel_center(r, index, (unsigned)(i % 8), (unsigned)(i / 8 % 8), (unsigned)(i / 64), centre) != NELF_OK)
                abort();
            g_sink += (float)centre[0];
            if (brick.reflection) { /* format 1.3: the voxel's normal, scale and lobe-table corners */
                float normal[3], weight[4];
                uint32_t node[4];
                g_sink += nelf_reflection_voxel(brick.reflection + i * NELF_REFLECTION_VALUES, normal);
                nelf_lobe_table_corners(normal, node, weight);
                if (node[0] >= NELF_LOBE_TABLE_HEIGHT * NELF_LOBE_TABLE_WIDTH ||
                    node[3] >= NELF_LOBE_TABLE_HEIGHT * NELF_LOBE_TABLE_WIDTH)
                    abort();
                g_sink += normal[0] + weight[0] + (float)brick.stored_reflection[i * NELF_REFLECTION_VALUES];
            }
        }
        if ((brick.fine_density != NULL) != (h->fine_density_factor != 0)) abort();
        if (brick.fine_density) { /* format 1.4: every fine voxel's density, some fine centres */
            unsigned edge = NELF_BRICK_SIZE * h->fine_density_factor;
            size_t count = (size_t)edge * edge * edge;
            if (h->fine_density_factor > NELF_MAX_FINE_DENSITY_FACTOR) abort();
            for (i = 0; i < count; i++) g_sink += brick.fine_density[i];
            for (i = 0; i < count; i += 997) {
                if (nelf_fine_voxel_center(r, index, (unsigned)(i % edge), (unsigned)(i / edge % edge),
                                           (unsigned)(i / edge / edge), centre) != NELF_OK)
                    abort();
                g_sink += (float)centre[2];
            }
            if (nelf_fine_voxel_center(r, index, edge, 0, 0, centre) != NELF_ERR_INVALID_ARGUMENT) abort();
        }
    }
    if (h->brick_count > 0) (void)nelf_voxel_transport(r, h->brick_count / 2, 511, lt);
    (void)nelf_verify(r);
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
    nelf_reader *r = nelf_create();
    if (!r) return 0;
    if (nelf_open_memory(r, data, size) == NELF_OK) exercise(r);
    /* Reuse after a failure or success: open again, verify first this time. */
    if (nelf_open_memory(r, data, size) == NELF_OK && nelf_verify(r) == NELF_OK) exercise(r);
    g_sink += (float)strlen(nelf_error_detail(r)) + (float)strlen(nelf_error_name(nelf_last_result(r)));
    nelf_destroy(r);
    return 0;
}
