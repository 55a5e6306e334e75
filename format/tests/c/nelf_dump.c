/*
 * Test driver for include/nelf.h, run by format/tests/c_reader.rs (compiled there
 * with -std=c99 -Wall -Wextra -Werror and AddressSanitizer + UBSan).
 *
 *   nelf_dump dump FILE LIGHT mem|path full|hashed
 *       Opens FILE (from memory or by path), verifies it, and prints the header, the
 *       section table, the metadata, the PCA model, the view-dependent parameters (if
 *       any), the reflection part's parameters (if any), the view harmonics, octahedral
 *       decodings and lobe-table corners of a few fixed directions, then every brick's
 *       voxels (full: one line per voxel with density, centre, coefficients, T and the
 *       relit radiance under LIGHT both ways, with a view part the view coefficients and
 *       T toward the eye at EYE, with a reflection part its three values, the decoded
 *       normal and the scale; hashed: one line per brick with XXH3 hashes of the same
 *       numbers); with a fine density (1.4) one more line per brick: every fine density
 *       value (full) or their hash, and the hash of every fine voxel's centre. Floats are
 *       printed as their bit patterns in hex
 *       so that the Rust side compares them exactly. Exit 1 with "error NAME detail"
 *       if the file is refused.
 *   nelf_dump check BUNDLE SCRATCH
 *       BUNDLE holds many files (u32 name length, name, u64 length, bytes). For each,
 *       prints one tab-separated line: index, the result of open + verify from memory
 *       ("whole"), of open + reading every brick + verify ("random"), of open + verify
 *       by path (the bytes written to SCRATCH first), the peak bytes the reader
 *       allocated, and the detail message of the whole read.
 */
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* Count what the reader allocates: a size header in front of every block. */
static size_t g_current, g_peak;
static void *counting_malloc(size_t n) {
    unsigned char *p = (unsigned char *)malloc(n + 16);
    if (!p) return NULL;
    memcpy(p, &n, sizeof n);
    g_current += n;
    if (g_current > g_peak) g_peak = g_current;
    return p + 16;
}
static void counting_free(void *q) {
    size_t n;
    unsigned char *p;
    if (!q) return;
    p = (unsigned char *)q - 16;
    memcpy(&n, p, sizeof n);
    g_current -= n;
    free(p);
}
#define NELF_MALLOC(n) counting_malloc(n)
#define NELF_FREE(p) counting_free(p)
#define NELF_IMPLEMENTATION
#include "nelf.h"

static void die(const char *what) {
    fprintf(stderr, "nelf_dump: %s\n", what);
    exit(2);
}

static unsigned char *read_file(const char *path, size_t *size) {
    FILE *f = fopen(path, "rb");
    unsigned char *data;
    long n = 0;
    if (!f) die("cannot open input");
    if (fseek(f, 0, SEEK_END) != 0 || (n = ftell(f)) < 0 || fseek(f, 0, SEEK_SET) != 0) die("cannot size input");
    data = (unsigned char *)malloc((size_t)n + 1);
    if (!data) die("out of memory");
    if (n && fread(data, 1, (size_t)n, f) != (size_t)n) die("short read");
    fclose(f);
    *size = (size_t)n;
    return data;
}

static uint32_t fbits(float f) {
    uint32_t u;
    memcpy(&u, &f, sizeof u);
    return u;
}
static uint64_t dbits(double d) {
    uint64_t u;
    memcpy(&u, &d, sizeof u);
    return u;
}

/* XXH3 of a float array's little-endian bytes. */
static uint64_t hash_floats(const float *v, size_t n) {
    unsigned char *bytes = (unsigned char *)malloc(4 * n + 1);
    size_t i;
    uint64_t h;
    if (!bytes) die("out of memory");
    for (i = 0; i < n; i++) {
        uint32_t u = fbits(v[i]);
        bytes[4 * i] = (unsigned char)u;
        bytes[4 * i + 1] = (unsigned char)(u >> 8);
        bytes[4 * i + 2] = (unsigned char)(u >> 16);
        bytes[4 * i + 3] = (unsigned char)(u >> 24);
    }
    h = XXH3_64bits(bytes, 4 * n);
    free(bytes);
    return h;
}

/* XXH3 of a double array's little-endian bytes. */
static uint64_t hash_doubles(const double *v, size_t n) {
    unsigned char *bytes = (unsigned char *)malloc(8 * n + 1);
    size_t i;
    int k;
    uint64_t h;
    if (!bytes) die("out of memory");
    for (i = 0; i < n; i++) {
        uint64_t u = dbits(v[i]);
        for (k = 0; k < 8; k++) bytes[8 * i + k] = (unsigned char)(u >> (8 * k));
    }
    h = XXH3_64bits(bytes, 8 * n);
    free(bytes);
    return h;
}

static void print_floats(const char *tag, const float *v, size_t n) {
    size_t i;
    printf("%s", tag);
    for (i = 0; i < n; i++) printf(" %08lx", (unsigned long)fbits(v[i]));
    printf("\n");
}

/* The eye the view-dependent transport is evaluated toward: omega = EYE - centre. */
static const double EYE[3] = {0.31, 0.17, 0.52};

/* Directions whose harmonics are printed (zero, axes, unnormalised, non-finite, overflowing). */
static const float HARMONIC_DIRECTIONS[][3] = {
    {0.0f, 0.0f, 0.0f}, {1.0f, 0.0f, 0.0f}, {0.0f, -2.0f, 0.0f}, {3.0f, 4.0f, 12.0f},
    {-0.3f, 0.7f, 0.2f}, {1e-30f, 2e-30f, -1e-30f}, {1e20f, 0.0f, 1.0f}, {0.0f, 0.0f, 0.0f},
};

/* Octahedral (u, v) pairs whose decoding is printed (inside, on and outside the square). */
static const float OCTAHEDRAL_POINTS[][2] = {
    {0.0f, 0.0f}, {1.0f, 1.0f}, {-1.0f, 1.0f}, {0.3f, -0.9f}, {2.0f, -3.0f}, {-0.5f, -0.5f}, {0.0f, -1.0f}, {-0.0f, 0.7f},
};

/* Light-frame directions whose lobe-table corners are printed (poles, the seam at phi = +-pi,
 * unnormalised, zero, non-finite). */
static const float LOBE_DIRECTIONS[][3] = {
    {0.0f, 1.0f, 0.0f}, {0.0f, -1.0f, 0.0f}, {0.0f, 0.0f, 1.0f}, {1e-4f, 0.0f, 1.0f}, {-1e-4f, 0.2f, 1.0f},
    {3.0f, 4.0f, -12.0f}, {-0.3f, 0.7f, 0.2f}, {0.0f, 0.0f, 0.0f}, {1e20f, 1e20f, 0.0f}, {0.6f, -0.3f, -0.74f},
};

static int dump(int argc, char **argv) {
    const char *path, *mode;
    unsigned char *data = NULL;
    size_t size = 0, meta_length, i;
    float light[NELF_ENV_TEXELS * 3];
    nelf_reader *r;
    nelf_result rc;
    const nelf_header *h;
    nelf_projected_light *projected;
    const char *meta;
    const nelf_view *view;
    const nelf_reflection *reflection;
    int full;
    uint32_t b, k, rank, per_view = 0;
    if (argc != 6) die("usage: dump FILE LIGHT mem|path full|hashed");
    path = argv[2];
    mode = argv[4];
    full = strcmp(argv[5], "full") == 0;
    {
        FILE *f = fopen(argv[3], "r");
        if (!f) die("cannot open light");
        for (i = 0; i < NELF_ENV_TEXELS * 3; i++) {
            unsigned long u;
            uint32_t u32;
            if (fscanf(f, "%lx", &u) != 1) die("bad light file");
            u32 = (uint32_t)u;
            memcpy(&light[i], &u32, sizeof u32);
        }
        fclose(f);
    }
    r = nelf_create();
    if (!r) die("out of memory");
    if (strcmp(mode, "mem") == 0) {
        data = read_file(path, &size);
        rc = nelf_open_memory(r, data, size);
    } else {
        rc = nelf_open_path(r, path);
    }
    if (rc == NELF_OK) rc = nelf_verify(r);
    if (rc != NELF_OK) {
        printf("error %s %s\n", nelf_error_name(rc), nelf_error_detail(r));
        nelf_destroy(r);
        free(data);
        return 1;
    }
    h = nelf_get_header(r);
    rank = h->pca_rank;
    printf("header %u %u %lu %016llx", h->version_major, h->version_minor, (unsigned long)h->section_count,
           (unsigned long long)h->flags);
    for (i = 0; i < 3; i++) printf(" %016llx", (unsigned long long)dbits(h->bbox_min_m[i]));
    for (i = 0; i < 3; i++) printf(" %016llx", (unsigned long long)dbits(h->bbox_max_m[i]));
    printf(" %016llx %lu %lu %lu %lu %lu", (unsigned long long)dbits(h->voxel_size_m), (unsigned long)h->grid_bricks[0],
           (unsigned long)h->grid_bricks[1], (unsigned long)h->grid_bricks[2], (unsigned long)h->brick_count,
           (unsigned long)h->chunk_bricks);
    for (i = 0; i < 9; i++) printf(" %016llx", (unsigned long long)dbits(h->world_from_light[i]));
    printf(" %u %u %lu %lu %lu %llu %016llx\n", h->env_height, h->env_width, (unsigned long)rank,
           (unsigned long)h->coefficient_encoding, (unsigned long)h->fine_density_factor,
           (unsigned long long)h->file_size, (unsigned long long)h->header_checksum);
    for (i = 0; i < nelf_section_count(r); i++) {
        const nelf_section *s = nelf_get_section(r, (uint32_t)i);
        printf("section %lu %02x%02x%02x%02x %u %u %lu %llu %llu %llu %016llx\n", (unsigned long)i,
               (unsigned char)s->kind[0], (unsigned char)s->kind[1], (unsigned char)s->kind[2],
               (unsigned char)s->kind[3], s->flags, s->codec, (unsigned long)s->shuffle,
               (unsigned long long)s->offset, (unsigned long long)s->stored_length,
               (unsigned long long)s->raw_length, (unsigned long long)s->checksum);
    }
    meta = nelf_metadata(r, &meta_length);
    printf("meta ");
    for (i = 0; i < meta_length; i++) printf("%02x", (unsigned char)meta[i]);
    printf("\n");
    if (full) {
        print_floats("mean", nelf_pca_mean(r), NELF_LT_DIM);
        print_floats("basis", nelf_pca_basis(r), (size_t)NELF_LT_DIM * rank);
    } else {
        printf("mean %016llx\n", (unsigned long long)hash_floats(nelf_pca_mean(r), NELF_LT_DIM));
        printf("basis %016llx\n", (unsigned long long)hash_floats(nelf_pca_basis(r), (size_t)NELF_LT_DIM * rank));
    }
    if (nelf_quant_scale(r)) {
        print_floats("scale", nelf_quant_scale(r), rank);
        print_floats("offset", nelf_quant_offset(r), rank);
    }
    view = nelf_get_view(r);
    if (view) {
        per_view = view->coefficients_per_voxel;
        if (per_view != view->lobe_count * view->rank) die("view coefficients per voxel disagree");
        printf("view %lu %lu %lu\n", (unsigned long)view->lobe_count, (unsigned long)view->rank,
               (unsigned long)view->encoding);
        if (full) {
            print_floats("view_lobes", view->lobes, (size_t)NELF_VIEW_HARMONICS * view->lobe_count);
            print_floats("view_basis", view->basis, (size_t)NELF_LT_DIM * view->rank);
        } else {
            printf("view_lobes %016llx\n",
                   (unsigned long long)hash_floats(view->lobes, (size_t)NELF_VIEW_HARMONICS * view->lobe_count));
            printf("view_basis %016llx\n", (unsigned long long)hash_floats(view->basis, (size_t)NELF_LT_DIM * view->rank));
        }
        if (view->scale) {
            print_floats("view_scale", view->scale, per_view);
            print_floats("view_offset", view->offset, per_view);
        }
    }
    reflection = nelf_get_reflection(r);
    if (reflection) {
        printf("reflection %lu %08lx\n", (unsigned long)reflection->eye_count, (unsigned long)fbits(reflection->exponent));
        print_floats("reflection_eyes", &reflection->eyes_m[0][0], 3 * (size_t)reflection->eye_count);
        print_floats("reflection_scale", reflection->scale, NELF_REFLECTION_VALUES);
        print_floats("reflection_offset", reflection->offset, NELF_REFLECTION_VALUES);
    }
    {
        float n[3 * 8];
        for (i = 0; i < 8; i++) nelf_octahedral_decode(OCTAHEDRAL_POINTS[i][0], OCTAHEDRAL_POINTS[i][1], n + 3 * i);
        print_floats("octahedral", n, 3 * 8);
        printf("lobe_corners");
        for (i = 0; i < 10; i++) {
            uint32_t index[4];
            float weight[4];
            nelf_lobe_table_corners(LOBE_DIRECTIONS[i], index, weight);
            for (k = 0; k < 4; k++) printf(" %lu:%08lx", (unsigned long)index[k], (unsigned long)fbits(weight[k]));
        }
        printf("\n");
    }
    {
        float y[NELF_VIEW_HARMONICS * 8];
        float nan_direction[3];
        for (i = 0; i < 8; i++) nelf_view_harmonics(HARMONIC_DIRECTIONS[i], y + NELF_VIEW_HARMONICS * i);
        nan_direction[0] = strtof("nan", NULL); /* the last direction: NaN */
        nan_direction[1] = nan_direction[2] = 1.0f;
        nelf_view_harmonics(nan_direction, y + NELF_VIEW_HARMONICS * 7);
        print_floats("harmonics", y, NELF_VIEW_HARMONICS * 8);
    }
    projected = (nelf_projected_light *)malloc(sizeof *projected);
    if (!projected) die("out of memory");
    if (nelf_project_light(r, light, projected) != NELF_OK) die("projection failed");
    print_floats("light_mean", projected->mean_rgb, 3);
    print_floats("light_components", &projected->component_rgb[0][0], 3 * (size_t)rank);
    for (b = 0; b < h->brick_count; b++) {
        nelf_brick brick;
        float *lt = (float *)malloc(sizeof(float) * NELF_LT_DIM * NELF_BRICK_VOXELS);
        float *toward = (float *)malloc(sizeof(float) * NELF_LT_DIM * NELF_BRICK_VOXELS);
        float *relit = (float *)malloc(sizeof(float) * 6 * NELF_BRICK_VOXELS);
        double *centre = (double *)malloc(sizeof(double) * 3 * NELF_BRICK_VOXELS);
        float *shape = (float *)malloc(sizeof(float) * 4 * NELF_BRICK_VOXELS); /* normal and scale */
        float check[NELF_LT_DIM];
        uint32_t v;
        if (!lt || !toward || !relit || !centre || !shape) die("out of memory");
        rc = nelf_read_brick(r, b, &brick);
        if (rc != NELF_OK) {
            printf("error %s %s\n", nelf_error_name(rc), nelf_error_detail(r));
            free(lt);
            free(toward);
            free(relit);
            free(centre);
            free(shape);
            break;
        }
        if ((brick.view_coefficients != NULL) != (view != NULL)) die("view coefficients without a view part");
        if ((brick.reflection != NULL) != (reflection != NULL)) die("reflection values without a reflection part");
        if ((brick.stored_reflection != NULL) != (reflection != NULL)) die("stored reflection codes without a reflection part");
        if ((brick.fine_density != NULL) != (h->fine_density_factor != 0)) die("fine density without a factor");
        if (nelf_find_brick(r, brick.coord[0], brick.coord[1], brick.coord[2]) != (int64_t)b) die("find_brick disagrees");
        for (v = 0; v < NELF_BRICK_VOXELS; v++) {
            const float *c = brick.coefficients + (size_t)v * rank;
            float *t = lt + (size_t)v * NELF_LT_DIM;
            nelf_reconstruct(r, c, rank, t);
            nelf_relight(projected, c, rank, relit + 6 * v);
            nelf_shade(t, light, relit + 6 * v + 3);
            if (nelf_voxel_center(r, b, v % 8, (v / 8) % 8, v / 64, centre + 3 * v) != NELF_OK) die("voxel_center failed");
            if (view) {
                float omega[3];
                for (k = 0; k < 3; k++) omega[k] = (float)(EYE[k] - centre[3 * v + k]);
                memcpy(toward + (size_t)v * NELF_LT_DIM, t, sizeof(float) * NELF_LT_DIM);
                nelf_add_view_transport(r, brick.view_coefficients + (size_t)v * per_view, omega,
                                        toward + (size_t)v * NELF_LT_DIM);
            }
            if (reflection) {
                const float *values = brick.reflection + (size_t)v * NELF_REFLECTION_VALUES;
                const unsigned char *codes = brick.stored_reflection + (size_t)v * NELF_REFLECTION_VALUES;
                for (k = 0; k < NELF_REFLECTION_VALUES; k++) /* the dequantization rule, applied to the codes */
                    if (fbits(values[k]) != fbits(reflection->offset[k] + reflection->scale[k] * (float)codes[k]))
                        die("reflection values disagree with their codes");
                shape[4 * v + 3] = nelf_reflection_voxel(values, shape + 4 * v);
            }
        }
        if (view) { /* nelf_voxel_transport_toward gives the same T(x, omega) */
            float omega[3];
            for (k = 0; k < 3; k++) omega[k] = (float)(EYE[k] - centre[3 * 301 + k]);
            if (nelf_voxel_transport_toward(r, b, 301, omega, check) != NELF_OK) die("voxel_transport_toward failed");
            if (memcmp(check, toward + 301 * NELF_LT_DIM, sizeof check) != 0) die("voxel_transport_toward disagrees");
        }
        /* nelf_voxel_transport gives the same T (it re-reads the cached brick). */
        if (nelf_voxel_transport(r, b, 137, check) != NELF_OK) die("voxel_transport failed");
        if (memcmp(check, lt + 137 * NELF_LT_DIM, sizeof check) != 0) die("voxel_transport disagrees");
        if (nelf_read_brick(r, b, &brick) != NELF_OK) die("re-read failed");
        if (full) {
            printf("brick %lu %u %u %u\n", (unsigned long)b, brick.coord[0], brick.coord[1], brick.coord[2]);
            for (v = 0; v < NELF_BRICK_VOXELS; v++) {
                printf("v %lu %08lx %016llx %016llx %016llx", (unsigned long)((uint64_t)b * NELF_BRICK_VOXELS + v),
                       (unsigned long)fbits(brick.density[v]), (unsigned long long)dbits(centre[3 * v]),
                       (unsigned long long)dbits(centre[3 * v + 1]), (unsigned long long)dbits(centre[3 * v + 2]));
                for (k = 0; k < rank; k++) printf(" %08lx", (unsigned long)fbits(brick.coefficients[(size_t)v * rank + k]));
                printf(" |");
                for (k = 0; k < NELF_LT_DIM; k++) printf(" %08lx", (unsigned long)fbits(lt[(size_t)v * NELF_LT_DIM + k]));
                printf(" |");
                for (k = 0; k < 6; k++) printf(" %08lx", (unsigned long)fbits(relit[6 * v + k]));
                if (view) {
                    printf(" |");
                    for (k = 0; k < per_view; k++)
                        printf(" %08lx", (unsigned long)fbits(brick.view_coefficients[(size_t)v * per_view + k]));
                    printf(" |");
                    for (k = 0; k < NELF_LT_DIM; k++) printf(" %08lx", (unsigned long)fbits(toward[(size_t)v * NELF_LT_DIM + k]));
                }
                if (reflection) {
                    printf(" |");
                    for (k = 0; k < NELF_REFLECTION_VALUES; k++)
                        printf(" %08lx", (unsigned long)fbits(brick.reflection[(size_t)v * NELF_REFLECTION_VALUES + k]));
                    printf(" |");
                    for (k = 0; k < 4; k++) printf(" %08lx", (unsigned long)fbits(shape[4 * v + k]));
                }
                printf("\n");
            }
        } else {
            printf("brick %lu %u %u %u %016llx %016llx %016llx %016llx %016llx\n", (unsigned long)b, brick.coord[0],
                   brick.coord[1], brick.coord[2], (unsigned long long)hash_floats(brick.density, NELF_BRICK_VOXELS),
                   (unsigned long long)hash_doubles(centre, 3 * NELF_BRICK_VOXELS),
                   (unsigned long long)hash_floats(brick.coefficients, (size_t)NELF_BRICK_VOXELS * rank),
                   (unsigned long long)hash_floats(lt, (size_t)NELF_LT_DIM * NELF_BRICK_VOXELS),
                   (unsigned long long)hash_floats(relit, 6 * NELF_BRICK_VOXELS));
            if (view)
                printf("view_brick %lu %016llx %016llx\n", (unsigned long)b,
                       (unsigned long long)hash_floats(brick.view_coefficients, (size_t)NELF_BRICK_VOXELS * per_view),
                       (unsigned long long)hash_floats(toward, (size_t)NELF_LT_DIM * NELF_BRICK_VOXELS));
            if (reflection)
                printf("reflection_brick %lu %016llx %016llx\n", (unsigned long)b,
                       (unsigned long long)hash_floats(brick.reflection, (size_t)NELF_REFLECTION_VALUES * NELF_BRICK_VOXELS),
                       (unsigned long long)hash_floats(shape, 4 * (size_t)NELF_BRICK_VOXELS));
        }
        if (brick.fine_density) { /* format 1.4: the fine density and the centres of its fine voxels */
            uint32_t edge = NELF_BRICK_SIZE * h->fine_density_factor, n = edge * edge * edge;
            double *fine_centre = (double *)malloc(sizeof(double) * 3 * n), c[3];
            if (!fine_centre) die("out of memory");
            for (v = 0; v < n; v++)
                if (nelf_fine_voxel_center(r, b, v % edge, (v / edge) % edge, v / (edge * edge), fine_centre + 3 * v) !=
                    NELF_OK)
                    die("fine_voxel_center failed");
            if (nelf_fine_voxel_center(r, b, 0, edge, 0, c) != NELF_ERR_INVALID_ARGUMENT)
                die("fine_voxel_center accepted a fine voxel outside the brick");
            if (full) {
                printf("fine %lu", (unsigned long)b);
                for (v = 0; v < n; v++) printf(" %08lx", (unsigned long)fbits(brick.fine_density[v]));
                printf(" | %016llx\n", (unsigned long long)hash_doubles(fine_centre, 3 * (size_t)n));
            } else {
                printf("fine_brick %lu %016llx %016llx\n", (unsigned long)b,
                       (unsigned long long)hash_floats(brick.fine_density, n),
                       (unsigned long long)hash_doubles(fine_centre, 3 * (size_t)n));
            }
            free(fine_centre);
        } else {
            double c[3];
            if (nelf_fine_voxel_center(r, b, 0, 0, 0, c) != NELF_ERR_INVALID_ARGUMENT)
                die("fine_voxel_center without a fine density");
        }
        free(shape);
        free(toward);
        free(lt);
        free(relit);
        free(centre);
    }
    if (rc == NELF_OK) { /* misuse is refused, not undefined */
        nelf_brick brick;
        if (nelf_read_brick(r, h->brick_count, &brick) != NELF_ERR_BRICK_OUT_OF_RANGE) die("out-of-range brick accepted");
        if (nelf_find_brick(r, 70000, 0, 0) != -1) die("find_brick found a brick outside the grid");
        printf("end\n");
    }
    free(projected);
    nelf_destroy(r);
    free(data);
    return rc == NELF_OK ? 0 : 1;
}

/* open + verify ("whole"), or open + every brick + verify ("random"). */
static nelf_result check_one(nelf_reader *r, const unsigned char *data, size_t size, const char *path, int random,
                             char *detail) {
    nelf_result rc = path ? nelf_open_path(r, path) : nelf_open_memory(r, data, size);
    if (rc == NELF_OK && random) {
        const nelf_header *h = nelf_get_header(r);
        uint32_t b;
        for (b = 0; b < h->brick_count && rc == NELF_OK; b++) {
            nelf_brick brick;
            rc = nelf_read_brick(r, b, &brick);
        }
    }
    if (rc == NELF_OK) rc = nelf_verify(r);
    if (detail) {
        strncpy(detail, nelf_error_detail(r), NELF_DETAIL_SIZE - 1);
        detail[NELF_DETAIL_SIZE - 1] = '\0';
    }
    return rc;
}

static int check(int argc, char **argv) {
    size_t size, at = 0, index = 0;
    unsigned char *bundle;
    nelf_reader *r;
    if (argc != 4) die("usage: check BUNDLE SCRATCH");
    bundle = read_file(argv[2], &size);
    r = nelf_create();
    if (!r) die("out of memory");
    while (at < size) {
        uint32_t name_length;
        uint64_t length;
        unsigned char *copy;
        char detail[NELF_DETAIL_SIZE];
        nelf_result whole, random, by_path;
        size_t peak;
        FILE *f;
        if (size - at < 4) die("bad bundle");
        name_length = nelf__u32(bundle + at);
        at += 4 + name_length;
        if (at > size || size - at < 8) die("bad bundle");
        length = nelf__u64(bundle + at);
        at += 8;
        if (length > size - at) die("bad bundle");
        /* An exact-size copy, so that ASan sees any read past the end. */
        copy = (unsigned char *)malloc((size_t)length + (length == 0));
        if (!copy) die("out of memory");
        memcpy(copy, bundle + at, (size_t)length);
        at += (size_t)length;
        g_peak = g_current;
        whole = check_one(r, copy, (size_t)length, NULL, 0, detail);
        random = check_one(r, copy, (size_t)length, NULL, 1, NULL);
        peak = g_peak - g_current;
        f = fopen(argv[3], "wb");
        if (!f || (length && fwrite(copy, 1, (size_t)length, f) != (size_t)length) || fclose(f) != 0) die("cannot write scratch");
        by_path = check_one(r, NULL, 0, argv[3], 0, NULL);
        /* A failed open leaves the reader closed; destroy and recreate now and then
         * so that reuse and fresh readers are both exercised. */
        if (index % 7 == 0) {
            nelf_destroy(r);
            r = nelf_create();
            if (!r) die("out of memory");
        }
        printf("%lu\t%s\t%s\t%s\t%lu\t%s\n", (unsigned long)index, nelf_error_name(whole), nelf_error_name(random),
               nelf_error_name(by_path), (unsigned long)peak, detail);
        free(copy);
        index++;
    }
    nelf_destroy(r);
    free(bundle);
    if (g_current != 0) die("the reader leaked memory");
    return 0;
}

int main(int argc, char **argv) {
    if (argc >= 2 && strcmp(argv[1], "dump") == 0) return dump(argc, argv);
    if (argc >= 2 && strcmp(argv[1], "check") == 0) return check(argc, argv);
    die("usage: nelf_dump dump|check ...");
    return 2;
}
