/*
 * nelf.h: single-header C99 reader for `.nelf` relightable light-transport files
 * (format version 1.x, see format/SPEC.md in the nelf repository), including the
 * optional view-dependent parts of version 1.2 (sections VDEP and VCOF: harmonic lobes)
 * and 1.3 (sections VREF and VRCO: a glossy lobe about the mirror direction), and the
 * optional fine density of version 1.4 (section DNSF: the density on a lattice 2 or 4
 * times finer per axis, header field fine_density_factor).
 *
 * Use:   in exactly one .c file,
 *            #define NELF_IMPLEMENTATION
 *            #include "nelf.h"
 *        elsewhere just #include "nelf.h". Link with -lzstd -lxxhash -lm.
 *
 * The reader validates everything SPEC.md section 11 asks, in the same order as the
 * reference reader (`nelf-format`'s read.rs), and reports the first problem as a
 * distinct `nelf_result` code with a message naming where it is. Every allocation is
 * bounded before it is made: by the actual file length (brick list, chunk tables,
 * stored bytes of a section read from a FILE), or by the format's limits (PCA model
 * <= 591 360 bytes, QPRM <= 3 KiB, VDEP <= 593 236 bytes, VREF <= 224 bytes, metadata
 * <= 1 MiB, one decoded chunk <= 4 MiB and <= 32768 x its stored size, one brick of fine
 * density <= 128 KiB as floats).
 *
 * Numbers: reconstruction, relighting and shading follow the reference's arithmetic
 * operation by operation (float sums in ascending index order starting from -0.0f,
 * the light projection in double, the direction's length with sqrtf), so results are
 * bit-identical to the Rust reader when the compiler does not contract a*b+c into fused
 * multiply-adds: GCC in -std=c99 mode does not; otherwise pass -ffp-contract=off.
 * FLT_EVAL_METHOD must be 0 (any SSE2 or AArch64 target). nelf_lobe_table_corners calls
 * acosf and atan2f, which Rust's f32::acos and f32::atan2 take from the platform's C math
 * library too: its corners are bit-identical where both use the same one.
 *
 * A reader is not thread-safe (it caches one decoded chunk); use one per thread.
 *
 * Options (define before including the implementation):
 *   NELF_MALLOC(n) / NELF_FREE(p)      allocator (default malloc / free)
 *   NELF_API                           storage class of the API (default extern)
 *   NELF_FUZZING_IGNORE_CHECKSUMS      fuzzing builds only: checksum mismatches are
 *                                      ignored so mutated inputs reach the decoders
 *
 * Licence: MIT OR Apache-2.0, like the rest of the nelf project.
 */
#ifndef NELF_H
#define NELF_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

#ifndef NELF_API
#define NELF_API extern
#endif

/* The format's fixed numbers. */
#define NELF_VERSION_MAJOR 1         /* the major version this reader reads */
#define NELF_HEADER_SIZE 256
#define NELF_SECTION_ENTRY_SIZE 48
#define NELF_MAX_SECTIONS 64
#define NELF_BRICK_SIZE 8
#define NELF_BRICK_VOXELS 512
#define NELF_ENV_HEIGHT 8
#define NELF_ENV_WIDTH 16
#define NELF_ENV_TEXELS 128          /* lighting directions, index row * 16 + col */
#define NELF_LT_DIM 384              /* light-transport vector: 3 channels x 128 texels */
#define NELF_MAX_RANK 384
#define NELF_ENCODING_U8_AFFINE 1
#define NELF_ENCODING_F16 2
#define NELF_FLAG_SIGNED_DENSITY 1u  /* header flag bit 0: DENS may hold negative values */
#define NELF_VIEW_HARMONICS 9        /* harmonics a view lobe weighs: degrees 0, 1 and 2 (1.2) */
#define NELF_REFLECTION_VALUES 3     /* VRCO values per voxel: octahedral normal u, v and scale s (1.3) */
#define NELF_MAX_REFLECTION_EYES 16  /* eyes a reflection part averages over: 1..16 (1.3) */
#define NELF_MAX_REFLECTION_EXPONENT 200.0f /* the lobe exponent lies in 1..200 (1.3) */
#define NELF_LOBE_TABLE_HEIGHT 64    /* rows of the reflection lobe's direction table (1.3) */
#define NELF_LOBE_TABLE_WIDTH 128    /* columns of the reflection lobe's direction table (1.3) */
#define NELF_MAX_FINE_DENSITY_FACTOR 4 /* fine_density_factor F: 0 (none), 2 or 4 (1.4) */
#define NELF_DETAIL_SIZE 512

/*
 * Result codes: 0 is success, every other value one kind of failure. The reader's
 * detail message (nelf_error_detail) says where (section, chunk, voxel, field).
 */
#define NELF__RESULTS(X)                                                                     \
    X(NELF_OK, "success")                                                                    \
    X(NELF_ERR_INVALID_ARGUMENT, "invalid argument")                                         \
    X(NELF_ERR_NOT_OPEN, "no file is open in this reader")                                   \
    X(NELF_ERR_OUT_OF_MEMORY, "out of memory")                                               \
    X(NELF_ERR_IO, "I/O error")                                                              \
    X(NELF_ERR_BAD_MAGIC, "not a .nelf file (bad magic)")                                    \
    X(NELF_ERR_TRUNCATED, "truncated file")                                                  \
    X(NELF_ERR_UNSUPPORTED_VERSION, "unsupported major version")                             \
    X(NELF_ERR_HEADER_SIZE, "header_size is not 256")                                        \
    X(NELF_ERR_SECTION_ENTRY_SIZE, "section_entry_size is not 48")                           \
    X(NELF_ERR_FILE_SIZE_MISMATCH, "file is longer than its header's file_size")             \
    X(NELF_ERR_TOO_MANY_SECTIONS, "more than 64 sections")                                   \
    X(NELF_ERR_UNSUPPORTED_FEATURE, "file requires an unknown feature flag")                 \
    X(NELF_ERR_NONFINITE_HEADER, "non-finite value in a header field")                       \
    X(NELF_ERR_GRID, "invalid grid (voxel size or grid_bricks)")                             \
    X(NELF_ERR_BBOX_MAX, "bbox_max disagrees with bbox_min + 8 grid_bricks voxel_size")      \
    X(NELF_ERR_BRICK_SIZE, "brick_size is not 8")                                            \
    X(NELF_ERR_NOT_A_ROTATION, "world_from_light is not a rotation")                         \
    X(NELF_ERR_ENV_SIZE, "lighting basis is not 8 x 16")                                     \
    X(NELF_ERR_BAD_RANK, "PCA rank outside 1..384")                                          \
    X(NELF_ERR_BAD_ENCODING, "unknown coefficient_encoding")                                 \
    X(NELF_ERR_CHUNK_BRICKS, "chunk_bricks is 0")                                            \
    X(NELF_ERR_CHUNK_TOO_LARGE, "a chunk would decode to more than 4 MiB")                   \
    X(NELF_ERR_HEADER_CHECKSUM, "header and section table checksum mismatch")                \
    X(NELF_ERR_MISALIGNED, "section offset is not 8-byte aligned")                           \
    X(NELF_ERR_SECTION_OUT_OF_BOUNDS, "section lies outside the data area")                  \
    X(NELF_ERR_DUPLICATE_SECTION, "a section kind appears twice")                            \
    X(NELF_ERR_SECTIONS_OVERLAP, "two sections overlap")                                     \
    X(NELF_ERR_UNKNOWN_REQUIRED_SECTION, "unknown section marked required")                  \
    X(NELF_ERR_BAD_CODEC, "codec or shuffle not allowed for this section")                   \
    X(NELF_ERR_SECTION_LENGTH, "decoded length disagrees with the header's counts")          \
    X(NELF_ERR_METADATA_TOO_LARGE, "metadata decodes to more than 1 MiB")                    \
    X(NELF_ERR_IMPLAUSIBLE_LENGTH, "decoded length impossible for the stored length")        \
    X(NELF_ERR_MISSING_SECTION, "a required section is missing")                             \
    X(NELF_ERR_SECTION_CHECKSUM, "section checksum mismatch")                                \
    X(NELF_ERR_ZSTD, "zstd decoding failed or gave the wrong length")                        \
    X(NELF_ERR_INVALID_BRICKS, "brick outside the grid, unsorted or repeated")               \
    X(NELF_ERR_NONFINITE_PCA, "non-finite value in the PCA mean or basis")                   \
    X(NELF_ERR_NONFINITE_QPRM, "non-finite 8-bit dequantization parameter")                  \
    X(NELF_ERR_NEGATIVE_SCALE, "negative 8-bit dequantization scale")                        \
    X(NELF_ERR_UNEXPECTED_QPRM, "QPRM section present with f16 coefficients")                \
    X(NELF_ERR_METADATA_JSON, "metadata is not valid JSON")                                  \
    X(NELF_ERR_METADATA_NOT_OBJECT, "metadata is not a JSON object")                         \
    X(NELF_ERR_CHUNK_COUNT, "chunk table larger than its section")                           \
    X(NELF_ERR_BAD_CHUNK_TABLE, "chunks do not tile their section")                          \
    X(NELF_ERR_CHUNK_CHECKSUM, "chunk checksum mismatch")                                    \
    X(NELF_ERR_NONFINITE_DENSITY, "non-finite density")                                      \
    X(NELF_ERR_NEGATIVE_DENSITY, "negative density without the signed-density flag")         \
    X(NELF_ERR_NONFINITE_COEFFICIENT, "non-finite f16 coefficient")                          \
    X(NELF_ERR_NONZERO_PADDING, "non-zero padding byte between sections")                    \
    X(NELF_ERR_BRICK_OUT_OF_RANGE, "brick index out of range")                               \
    X(NELF_ERR_BAD_VIEW, "malformed view-dependent part (VDEP and VCOF, or VREF and VRCO)")  \
    X(NELF_ERR_NONFINITE_VIEW, "non-finite value in the view part (lobes, basis, eyes, parameters)") \
    X(NELF_ERR_FINE_DENSITY_FACTOR, "fine_density_factor is not 0, 2 or 4, or disagrees with section DNSF")

#define NELF__ENUM_ENTRY(name, text) name,
typedef enum nelf_result { NELF__RESULTS(NELF__ENUM_ENTRY) NELF_RESULT_COUNT } nelf_result;
#undef NELF__ENUM_ENTRY

/* The 256-byte header, decoded (SPEC.md section 3). */
typedef struct nelf_header {
    uint16_t version_major;
    uint16_t version_minor;
    uint32_t header_size;
    uint32_t section_count;
    uint32_t section_entry_size;
    uint64_t flags;                /* bit 0: signed density */
    double bbox_min_m[3];
    double bbox_max_m[3];          /* as stored (checked against the grid) */
    double voxel_size_m;
    uint32_t grid_bricks[3];
    uint32_t brick_size;
    uint32_t brick_count;          /* B */
    uint32_t chunk_bricks;         /* N */
    double world_from_light[9];    /* row-major: d_world = M d_light */
    uint16_t env_height;
    uint16_t env_width;
    uint32_t pca_rank;             /* K */
    uint32_t coefficient_encoding; /* NELF_ENCODING_U8_AFFINE or NELF_ENCODING_F16 */
    uint32_t fine_density_factor;  /* F (1.4): 0 = no fine density, else 2 or 4 (section DNSF) */
    uint64_t file_size;
    uint64_t header_checksum;
} nelf_header;

/* One section-table entry (SPEC.md section 4). */
typedef struct nelf_section {
    char kind[5];                  /* the four kind bytes and a NUL */
    uint16_t flags;                /* bit 0: required */
    uint16_t codec;                /* 0 raw, 1 zstd, 2 chunked zstd */
    uint32_t shuffle;
    uint64_t offset;
    uint64_t stored_length;
    uint64_t raw_length;
    uint64_t checksum;
} nelf_section;

/* One brick from nelf_read_brick. The pointers belong to the reader and stay valid
 * until the next nelf_read_brick, nelf_verify, nelf_open_* or nelf_destroy. */
typedef struct nelf_brick {
    uint32_t index;
    uint16_t coord[3];                       /* brick coordinates in the grid (x, y, z) */
    const float *density;                    /* 512 sigma values (1/m), x fastest */
    const float *coefficients;               /* 512 x K dequantized, voxel-major */
    const unsigned char *stored_coefficients;/* 512 x K codes (u8) or little-endian f16 */
    /* The view-dependent part (1.2), NULL without one: 512 x R (R = J K_v) dequantized,
     * voxel-major, d_ji of a voxel at j * K_v + i; and as stored (u8 or f16). */
    const float *view_coefficients;
    const unsigned char *stored_view_coefficients;
    /* The reflection part (1.3), NULL without one: 512 x 3 dequantized values, voxel-major
     * (octahedral normal u, v, then the scale s; nelf_reflection_voxel decodes them); and
     * the 512 x 3 stored u8 codes. */
    const float *reflection;
    const unsigned char *stored_reflection;
    /* The fine density (1.4), NULL without one: 512 F^3 sigma values (1/m) on the brick's
     * 8F x 8F x 8F fine voxels, fine voxel (i, j, k) (each 0..8F-1) at i + 8F (j + 8F k);
     * nelf_fine_voxel_center gives its centre. A renderer that reads it takes the density
     * from it instead of `density` (SPEC.md section 8, "Fine density"). */
    const float *fine_density;
} nelf_brick;

/* The view-dependent part's parameters (format 1.2, section VDEP, SPEC.md section 6):
 * T(x, w) = T_pca(x) + sum_j Y_j(w) sum_i d_ji(x) V_i with Y_j(w) = sum_l lobes[j * 9 + l]
 * y_l(w) (nelf_view_harmonics). Pointers belong to the reader (valid while it is open). */
typedef struct nelf_view {
    uint32_t lobe_count;           /* J, 1..9 */
    uint32_t rank;                 /* K_v, >= 1, J K_v <= 384 */
    uint32_t coefficients_per_voxel; /* R = J K_v */
    uint32_t encoding;             /* of VCOF: NELF_ENCODING_U8_AFFINE or NELF_ENCODING_F16 */
    const float *lobes;            /* J x NELF_VIEW_HARMONICS, lobe-major */
    const float *basis;            /* K_v x 384, vector i at i * 384 (channel-major as PCAB) */
    const float *scale;            /* R 8-bit dequantization steps, NULL for f16 */
    const float *offset;           /* R 8-bit offsets, NULL for f16 */
} nelf_view;

/* The reflection part's parameters (format 1.3, section VREF, SPEC.md section 6): one glossy
 * lobe about the mirror direction r = 2 (n.w) n - w per voxel. Seen from world direction w
 * (voxel toward the eye), T(x, w)[c 128 + i] = T_pca[c 128 + i] + s (max(0, n.w) g_i(r) - hbar_i)
 * with g_i the Phong lobe max(0, r.w')^exponent integrated over light texel i (tabulated on
 * the lobe table, nelf_lobe_table_corners) and hbar_i the same averaged over the eyes. */
typedef struct nelf_reflection {
    uint32_t eye_count;            /* E, 1..16 */
    float exponent;                /* the lobe exponent, 1..200 */
    float eyes_m[NELF_MAX_REFLECTION_EYES][3]; /* the first E: world positions (metres) T_pca averages over */
    float scale[NELF_REFLECTION_VALUES];       /* VRCO dequantization: value_k = offset[k] + scale[k] code_k */
    float offset[NELF_REFLECTION_VALUES];      /* offset[2] >= 0: the scale s is never negative */
} nelf_reflection;

/* Lighting projected onto the PCA basis (SPEC.md section 8): the radiance of a voxel
 * with coefficients c is mean_rgb + sum_k c_k component_rgb[k]. */
typedef struct nelf_projected_light {
    uint32_t rank;
    float mean_rgb[3];
    float component_rgb[NELF_MAX_RANK][3];
} nelf_projected_light;

typedef struct nelf_reader nelf_reader;

/* --- errors --- */
/* A fixed human-readable sentence for a code ("unknown result code" if out of range). */
NELF_API const char *nelf_error_string(nelf_result result);
/* The code's identifier as text, e.g. "NELF_ERR_ZSTD". */
NELF_API const char *nelf_error_name(nelf_result result);

/* --- lifetime --- */
/* A new reader holding no file, or NULL when out of memory. */
NELF_API nelf_reader *nelf_create(void);
/* Closes any open file and frees everything. NULL is allowed. */
NELF_API void nelf_destroy(nelf_reader *reader);
/* Opens a file held in memory. The reader borrows `data` (no copy): keep it alive
 * and unchanged until the reader is destroyed or reopened. Validates the header, the
 * section table, the brick list, the PCA model, the 8-bit parameters, the view-dependent
 * or reflection part's parameters, the metadata and the chunk tables; chunks are decoded
 * later (nelf_read_brick, nelf_verify). */
NELF_API nelf_result nelf_open_memory(nelf_reader *reader, const void *data, size_t size);
/* Opens the file at `path` for random access (kept open; sizes up to LONG_MAX). */
NELF_API nelf_result nelf_open_path(nelf_reader *reader, const char *path);
/* Checks every remaining byte: every chunk (checksum, decoding, values), each section's
 * checksum, unknown optional sections' checksums, zero padding. Equivalent to the
 * reference's whole-file read. */
NELF_API nelf_result nelf_verify(nelf_reader *reader);
/* The last result of an open, verify or read call, and its detail message. */
NELF_API nelf_result nelf_last_result(const nelf_reader *reader);
NELF_API const char *nelf_error_detail(const nelf_reader *reader);

/* --- what open read (NULL / 0 when no file is open) --- */
NELF_API const nelf_header *nelf_get_header(const nelf_reader *reader);
NELF_API uint32_t nelf_section_count(const nelf_reader *reader);
NELF_API const nelf_section *nelf_get_section(const nelf_reader *reader, uint32_t index);
/* Brick coordinates, 3 per brick (x, y, z), in file (z, y, x) order. */
NELF_API const uint16_t *nelf_brick_coords(const nelf_reader *reader);
/* Index of the brick at (x, y, z) by binary search, or -1. */
NELF_API int64_t nelf_find_brick(const nelf_reader *reader, uint32_t x, uint32_t y, uint32_t z);
/* PCA mean (384 floats) and basis (K x 384, component k at k * 384). */
NELF_API const float *nelf_pca_mean(const nelf_reader *reader);
NELF_API const float *nelf_pca_basis(const nelf_reader *reader);
/* 8-bit dequantization parameters (K each), NULL for f16 coefficients. */
NELF_API const float *nelf_quant_scale(const nelf_reader *reader);
NELF_API const float *nelf_quant_offset(const nelf_reader *reader);
/* The metadata's raw UTF-8 JSON bytes (not NUL-terminated; checked to be a JSON
 * object). A file without metadata gives "{}" like the reference reader. */
NELF_API const char *nelf_metadata(const nelf_reader *reader, size_t *length);
/* The view-dependent part's parameters (1.2), NULL when the file has none (or none is open). */
NELF_API const nelf_view *nelf_get_view(const nelf_reader *reader);
/* The reflection part's parameters (1.3), NULL when the file has none (or none is open). A
 * file holds at most one of the two view-dependent parts. */
NELF_API const nelf_reflection *nelf_get_reflection(const nelf_reader *reader);

/* --- bricks and voxels --- */
/* Reads brick `index`: decodes (and checksums) only the chunk holding it (of DENS, COEF,
 * VCOF or VRCO, and DNSF), keeping that chunk so that bricks read in order decode each
 * chunk once; checks the brick's densities (fine ones too) and f16 values. */
NELF_API nelf_result nelf_read_brick(nelf_reader *reader, uint32_t index, nelf_brick *out);
/* Centre (metres) of voxel (i, j, k), each 0..7, of brick `index`; local voxel index
 * is i + 8 (j + 8 k). Returns NELF_ERR_BRICK_OUT_OF_RANGE for a bad index. */
NELF_API nelf_result nelf_voxel_center(const nelf_reader *reader, uint32_t brick_index, unsigned i,
                                       unsigned j, unsigned k, double out_m[3]);
/* Centre (metres) of fine voxel (i, j, k), each 0..8F-1, of brick `index` in a file with a
 * fine density (1.4, F = header fine_density_factor): per axis, in double,
 * bbox_min + (8F brick + i + 0.5) voxel_size / F; its local index (brick.fine_density) is
 * i + 8F (j + 8F k). NELF_ERR_INVALID_ARGUMENT without a fine density or for an index
 * out of range, NELF_ERR_BRICK_OUT_OF_RANGE for a bad brick. */
NELF_API nelf_result nelf_fine_voxel_center(const nelf_reader *reader, uint32_t brick_index, unsigned i,
                                            unsigned j, unsigned k, double out_m[3]);
/* T = mean + sum_{k < count} c_k B_k (count clamped to K), summed k = 0, 1, ... in float. */
NELF_API void nelf_reconstruct(const nelf_reader *reader, const float *coefficients, uint32_t count,
                               float out_lt[NELF_LT_DIM]);
/* T of voxel `local` (0..511) of brick `brick_index` (reads the brick). */
NELF_API nelf_result nelf_voxel_transport(nelf_reader *reader, uint32_t brick_index, uint32_t local,
                                          float out_lt[NELF_LT_DIM]);

/* --- the view-dependent part (format 1.2) --- */
/* The real spherical harmonics of degrees 0-2 at world direction `omega` (from the voxel
 * toward the eye; normalised first, in float with sqrtf; zero or non-finite gives zeros):
 * (c0, a y, a z, a x, b x y, b y z, c (3 z^2 - 1), b x z, b/2 (x^2 - y^2)),
 * c0 = 1/(2 sqrt pi), a = sqrt(3/4pi), b = sqrt(15/4pi), c = sqrt(5/16pi). */
NELF_API void nelf_view_harmonics(const float omega[3], float out[NELF_VIEW_HARMONICS]);
/* The lobe values Y_j(omega) = sum_l lobes[j * 9 + l] y_l(omega), j < J, summed l = 0, 1, ...
 * from -0.0f. Returns J (0, leaving out untouched, without a view part). */
NELF_API uint32_t nelf_view_lobe_values(const nelf_reader *reader, const float omega[3],
                                        float out[NELF_VIEW_HARMONICS]);
/* out_lt += sum_j Y_j(omega) sum_i d_ji V_i for one voxel's R dequantized view coefficients
 * (j then i ascending, w = Y_j d_ji, then out[e] += w V_i[e]). Nothing without a view part. */
NELF_API void nelf_add_view_transport(const nelf_reader *reader, const float *view_coefficients,
                                      const float omega[3], float out_lt[NELF_LT_DIM]);
/* T(x, omega) of voxel `local` of brick `brick_index`: nelf_voxel_transport plus, with a
 * view part, nelf_add_view_transport (reads the brick). */
NELF_API nelf_result nelf_voxel_transport_toward(nelf_reader *reader, uint32_t brick_index, uint32_t local,
                                                 const float omega[3], float out_lt[NELF_LT_DIM]);

/* --- the reflection part (format 1.3) --- */
/* Octahedral decoding of a unit vector: (u, v), each clamped to [-1, 1], maps to
 * p = (u, v, 1 - |u| - |v|), whose x, y fold to ((1 - |v|) sgn u, (1 - |u|) sgn v) where
 * p.z < 0 (sgn 0 = +1); then p / |p|, in float with sqrtf. */
NELF_API void nelf_octahedral_decode(float u, float v, float out[3]);
/* One voxel's reflection: its three dequantized values (brick.reflection + 3 * local) give
 * the unit normal (nelf_octahedral_decode of values 0 and 1) in out_normal; returns the
 * scale s = max(0, values[2]). */
NELF_API float nelf_reflection_voxel(const float values[NELF_REFLECTION_VALUES], float out_normal[3]);
/* The four nodes (row-major index row * 128 + col) and bilinear weights of light-frame
 * direction d in the 64 x 128 lat-long lobe table, node (row, col) at theta = (row + 1/2) pi / 64,
 * phi = (col + 1/2) 2 pi / 128 - pi: d normalised (zero or non-finite: +y), theta = acosf(y),
 * phi = atan2f(x, -z), t = theta 64 / pi - 1/2 clamped to [0, 63], s = (phi + pi) 128 / (2 pi) - 1/2
 * wrapping in phi; corners (t0, s0), (t0, s0 + 1), (t0 + 1, s0), (t0 + 1, s0 + 1), float throughout. */
NELF_API void nelf_lobe_table_corners(const float d[3], uint32_t out_index[4], float out_weight[4]);

/* --- lighting --- */
/* `light_rgb`: 128 texels x 3 channels (texel-major: light_rgb[t * 3 + c]), the mean
 * radiance of each texel of an 8 x 16 map in the asset's light frame. Computes
 * P_v,c = sum_t v[c * 128 + t] L[t][c] in double for the mean and each basis vector. */
NELF_API nelf_result nelf_project_light(const nelf_reader *reader, const float *light_rgb,
                                        nelf_projected_light *out);
/* radiance_c = mean_rgb[c] + sum_{k < count} c_k component_rgb[k][c] (count clamped to
 * the projection's rank), in float, k ascending. */
NELF_API void nelf_relight(const nelf_projected_light *light, const float *coefficients, uint32_t count,
                           float out_rgb[3]);
/* radiance_c = sum_t T[c * 128 + t] L[t][c] in float, t ascending: the unprojected
 * dot product of a light-transport vector with the lighting. */
NELF_API void nelf_shade(const float *lt, const float *light_rgb, float out_rgb[3]);
/* IEEE binary16 bits to float (exact). */
NELF_API float nelf_half_to_float(uint16_t bits);

#ifdef __cplusplus
}
#endif
#endif /* NELF_H */

/* ===================================================================================== */
#if defined(NELF_IMPLEMENTATION) && !defined(NELF_IMPLEMENTATION_DONE)
#define NELF_IMPLEMENTATION_DONE

#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <limits.h>
#include <math.h>
#include <xxhash.h>
#include <zstd.h>

#if defined(__clang__)
#pragma STDC FP_CONTRACT OFF
#endif

#ifndef NELF_MALLOC
#define NELF_MALLOC(n) malloc(n)
#define NELF_FREE(p) free(p)
#endif

#define NELF__CHUNK_ENTRY_SIZE 24u
#define NELF__MAX_CHUNK_RAW_BYTES ((uint64_t)4 << 20)
#define NELF__MAX_METADATA_BYTES ((uint64_t)1 << 20)
#define NELF__MAX_ZSTD_EXPANSION ((uint64_t)32768)
#define NELF__MAX_GRID_BRICKS 65536u
#define NELF__PIECE ((uint64_t)1 << 20)
#define NELF__VIEW_HEADER_SIZE 16u
/* Largest decoded VDEP: header, 9 lobes, 384 basis vectors, 384 (scale, offset) pairs. */
#define NELF__MAX_VIEW_PARAMS_BYTES \
    ((uint64_t)NELF__VIEW_HEADER_SIZE + 4u * NELF_VIEW_HARMONICS * NELF_VIEW_HARMONICS + \
     4u * (uint64_t)NELF_LT_DIM * NELF_LT_DIM + 8u * NELF_LT_DIM)

/* Decoded VREF with E eyes: u32 E, f32 exponent, E x 3 f32 eyes, 3 (scale, offset) pairs. */
#define NELF__REFLECTION_PARAMS_BYTES(eyes) (32u + 12u * (uint64_t)(eyes))
#define NELF__REFLECTION_BYTES_PER_BRICK ((uint64_t)NELF_REFLECTION_VALUES * NELF_BRICK_VOXELS)

enum {
    NELF__BRCK, NELF__DENS, NELF__DNSF, NELF__PCAB, NELF__QPRM, NELF__COEF, NELF__VDEP, NELF__VCOF, NELF__VREF,
    NELF__VRCO, NELF__META, NELF__KNOWN
};
static const char nelf__kinds[NELF__KNOWN][5] = {"BRCK", "DENS", "DNSF", "PCAB", "QPRM", "COEF",
                                                 "VDEP", "VCOF", "VREF", "VRCO", "META"};
/* The chunked sections, in the order a full read visits them (index "which"): DENS, COEF,
 * then the view-dependent part's values (VCOF or VRCO; a file holds at most one part),
 * then the fine density (DNSF). */
#define NELF__CHUNKED 4

struct nelf_reader {
    nelf_result status;
    char detail[NELF_DETAIL_SIZE];
    int is_open;
    /* source: a borrowed buffer or a FILE */
    const unsigned char *mem;
    FILE *file;
    uint64_t file_size;
    /* validated structure */
    nelf_header header;
    nelf_section sections[NELF_MAX_SECTIONS];
    int known[NELF__KNOWN]; /* table index of each known kind, or -1 */
    uint16_t *bricks;       /* 3 per brick */
    float *pca;             /* mean then basis, 384 (K + 1) */
    float *qparams;         /* scale[K] then offset[K], or NULL */
    unsigned char *meta;
    size_t meta_length;
    int has_view;                  /* VDEP and VCOF present */
    nelf_view view;
    float *view_params;            /* lobes, basis, scale[R], offset[R] (see view) */
    int has_reflection;            /* VREF and VRCO present */
    nelf_reflection reflection;
    int fine_slot;                 /* index "which" of DNSF among the chunked sections, or -1 */
    uint64_t fine_voxels;          /* fine voxels per brick, 512 F^3 (0 without DNSF) */
    int chunked;                   /* chunked sections: DENS, COEF, the view part's, DNSF: 2 to 4 */
    int chunked_kind[NELF__CHUNKED]; /* the known kind of each: DENS, COEF, then VCOF or VRCO, then DNSF */
    unsigned char *chunk_table[NELF__CHUNKED]; /* 24 bytes per chunk */
    uint64_t chunk_count;
    uint64_t bytes_per_brick[NELF__CHUNKED];
    /* working memory */
    ZSTD_DCtx *dctx;
    unsigned char *io;  size_t io_cap;   /* stored bytes read from a FILE */
    unsigned char *tmp; size_t tmp_cap;  /* decoded bytes before unshuffling */
    unsigned char *raw[NELF__CHUNKED]; size_t raw_cap[NELF__CHUNKED]; /* decoded chunk of each */
    int64_t cached_chunk;
    float *brick_density;   /* 512 */
    float *brick_coef;      /* 512 K */
    float *brick_view;      /* 512 R */
    float *brick_reflection; /* 512 x 3 */
    float *brick_fine_density; /* 512 F^3 */
};

/* ---------------------------------------------------------------- small helpers */

static const char *const nelf__names[] = {
#define NELF__NAME_ENTRY(name, text) #name,
    NELF__RESULTS(NELF__NAME_ENTRY)
#undef NELF__NAME_ENTRY
};
static const char *const nelf__texts[] = {
#define NELF__TEXT_ENTRY(name, text) text,
    NELF__RESULTS(NELF__TEXT_ENTRY)
#undef NELF__TEXT_ENTRY
};

NELF_API const char *nelf_error_string(nelf_result result) {
    if ((int)result < 0 || result >= NELF_RESULT_COUNT) return "unknown result code";
    return nelf__texts[result];
}

NELF_API const char *nelf_error_name(nelf_result result) {
    if ((int)result < 0 || result >= NELF_RESULT_COUNT) return "NELF_ERR_UNKNOWN";
    return nelf__names[result];
}

#if defined(__GNUC__)
__attribute__((format(printf, 3, 4)))
#endif
static nelf_result nelf__fail(nelf_reader *r, nelf_result code, const char *fmt, ...);
static nelf_result nelf__fail(nelf_reader *r, nelf_result code, const char *fmt, ...) {
    va_list args;
    va_start(args, fmt);
    vsnprintf(r->detail, sizeof r->detail, fmt, args);
    va_end(args);
    r->status = code;
    return code;
}

static nelf_result nelf__ok(nelf_reader *r) {
    r->status = NELF_OK;
    r->detail[0] = '\0';
    return NELF_OK;
}

static uint16_t nelf__u16(const unsigned char *p) { return (uint16_t)(p[0] | (p[1] << 8)); }
static uint32_t nelf__u32(const unsigned char *p) {
    return (uint32_t)p[0] | ((uint32_t)p[1] << 8) | ((uint32_t)p[2] << 16) | ((uint32_t)p[3] << 24);
}
static uint64_t nelf__u64(const unsigned char *p) {
    return (uint64_t)nelf__u32(p) | ((uint64_t)nelf__u32(p + 4) << 32);
}
static float nelf__f32(const unsigned char *p) {
    uint32_t u = nelf__u32(p);
    float f;
    memcpy(&f, &u, sizeof f);
    return f;
}
static double nelf__f64(const unsigned char *p) {
    uint64_t u = nelf__u64(p);
    double d;
    memcpy(&d, &u, sizeof d);
    return d;
}
static int nelf__finite32(float f) {
    uint32_t u;
    memcpy(&u, &f, sizeof u);
    return (u & 0x7F800000u) != 0x7F800000u;
}
static int nelf__finite64(double d) {
    uint64_t u;
    memcpy(&u, &d, sizeof u);
    return (u & 0x7FF0000000000000ull) != 0x7FF0000000000000ull;
}
static double nelf__abs(double d) { return d < 0.0 ? -d : d; }
static int nelf__half_finite(uint16_t h) { return (h & 0x7C00u) != 0x7C00u; }
/* Negative and not -0 (the reference compares to_f32() < 0). */
static int nelf__half_negative(uint16_t h) { return (h & 0x8000u) && (h & 0x7FFFu); }

NELF_API float nelf_half_to_float(uint16_t h) {
    uint32_t sign = (uint32_t)(h & 0x8000u) << 16;
    uint32_t exponent = (h >> 10) & 0x1Fu;
    uint32_t mantissa = h & 0x3FFu;
    uint32_t bits;
    float f;
    if (exponent == 0) {
        if (mantissa == 0) {
            bits = sign;
        } else { /* subnormal: normalise */
            uint32_t e = 113;
            while (!(mantissa & 0x400u)) {
                mantissa <<= 1;
                e--;
            }
            bits = sign | (e << 23) | ((mantissa & 0x3FFu) << 13);
        }
    } else if (exponent == 31) {
        bits = sign | 0x7F800000u | (mantissa << 13);
    } else {
        bits = sign | ((exponent + 112u) << 23) | (mantissa << 13);
    }
    memcpy(&f, &bits, sizeof f);
    return f;
}

/* Kind bytes as text for messages: ASCII printable kept, others escaped (\xNN). */
static const char *nelf__kind_text(const char kind[4], char out[17]) {
    size_t n = 0;
    int i;
    for (i = 0; i < 4; i++) {
        unsigned char c = (unsigned char)kind[i];
        if (c >= 0x20 && c < 0x7F && c != '\\' && c != '\'' && c != '"') {
            out[n++] = (char)c;
        } else {
            static const char hex[] = "0123456789abcdef";
            out[n++] = '\\';
            out[n++] = 'x';
            out[n++] = hex[c >> 4];
            out[n++] = hex[c & 15];
        }
    }
    out[n] = '\0';
    return out;
}

static uint64_t nelf__sat_mul(uint64_t a, uint64_t b) {
    if (a != 0 && b > UINT64_MAX / a) return UINT64_MAX;
    return a * b;
}

static int nelf__checksums_differ(uint64_t stored, uint64_t computed) {
#ifdef NELF_FUZZING_IGNORE_CHECKSUMS
    (void)stored;
    (void)computed;
    return 0;
#else
    return stored != computed;
#endif
}

/* Makes *buf hold at least `need` bytes (need is bounded by the caller). */
static nelf_result nelf__reserve(nelf_reader *r, unsigned char **buf, size_t *cap, uint64_t need) {
    unsigned char *p;
    if (need <= *cap && *buf) return NELF_OK;
    if (need > (uint64_t)SIZE_MAX - 1) return nelf__fail(r, NELF_ERR_OUT_OF_MEMORY, "cannot address %llu bytes", (unsigned long long)need);
    p = (unsigned char *)NELF_MALLOC((size_t)(need ? need : 1));
    if (!p) return nelf__fail(r, NELF_ERR_OUT_OF_MEMORY, "out of memory allocating %llu bytes", (unsigned long long)need);
    NELF_FREE(*buf);
    *buf = p;
    *cap = (size_t)(need ? need : 1);
    return NELF_OK;
}

/* Points *out at `length` bytes of the file at `offset` (bounds already checked against
 * the file size): into the caller's buffer for memory sources, else read into r->io. */
static nelf_result nelf__view(nelf_reader *r, uint64_t offset, uint64_t length, const unsigned char **out,
                              const char *what) {
    nelf_result rc;
    if (r->mem) {
        *out = r->mem + offset;
        return NELF_OK;
    }
    if ((rc = nelf__reserve(r, &r->io, &r->io_cap, length)) != NELF_OK) return rc;
    if (offset > (uint64_t)LONG_MAX || fseek(r->file, (long)offset, SEEK_SET) != 0)
        return nelf__fail(r, NELF_ERR_IO, "I/O error while reading %s: cannot seek to %llu", what,
                          (unsigned long long)offset);
    if (length && fread(r->io, 1, (size_t)length, r->file) != (size_t)length)
        return nelf__fail(r, NELF_ERR_IO, "I/O error while reading %s: short read of %llu bytes at %llu", what,
                          (unsigned long long)length, (unsigned long long)offset);
    *out = r->io;
    return NELF_OK;
}

/* Byte unshuffle (SPEC.md section 5): plain[i * width + b] = shuffled[b * n + i]. */
static void nelf__unshuffle(unsigned char *plain, const unsigned char *shuffled, size_t length, size_t width) {
    size_t n = length / width, r0, b, i;
    for (r0 = 0; r0 < n; r0 += 256) {
        size_t r1 = r0 + 256 < n ? r0 + 256 : n;
        for (b = 0; b < width; b++) {
            const unsigned char *plane = shuffled + b * n;
            for (i = r0; i < r1; i++) plain[i * width + b] = plane[i];
        }
    }
}

/* Decompresses `stored` into exactly `raw_length` bytes at dst (unshuffled with
 * `width`), using r->tmp when unshuffling. */
static nelf_result nelf__decode(nelf_reader *r, const unsigned char *stored, uint64_t stored_length,
                                unsigned char *dst, uint64_t raw_length, uint32_t width, const char *what) {
    unsigned char *target = dst;
    size_t n;
    nelf_result rc;
    if (width > 1) {
        if ((rc = nelf__reserve(r, &r->tmp, &r->tmp_cap, raw_length)) != NELF_OK) return rc;
        target = r->tmp;
    }
    n = ZSTD_decompressDCtx(r->dctx, target, (size_t)raw_length, stored, (size_t)stored_length);
    if (ZSTD_isError(n)) return nelf__fail(r, NELF_ERR_ZSTD, "zstd error in %s: %s", what, ZSTD_getErrorName(n));
    if ((uint64_t)n != raw_length)
        return nelf__fail(r, NELF_ERR_ZSTD, "zstd error in %s: decoded %llu bytes, expected %llu", what,
                          (unsigned long long)n, (unsigned long long)raw_length);
    if (width > 1) nelf__unshuffle(dst, r->tmp, (size_t)raw_length, width);
    return NELF_OK;
}

/* ---------------------------------------------------------------- metadata JSON */
/* A validator accepting exactly what serde_json (the reference) parses into a value:
 * RFC 8259 syntax, strings of valid UTF-8 without control characters, escapes with
 * paired surrogates, at most 127 nested arrays/objects, and numbers whose magnitude
 * does not round to infinity in binary64 (serde_json rejects those). */

typedef struct nelf__json {
    const unsigned char *p, *end;
    int remaining_depth;
    const char *error;
} nelf__json;

/* 2^1024 - 2^970: the smallest magnitude that rounds to infinity (ties to even). */
static const char nelf__json_inf_digits[] =
    "179769313486231580793728971405303415079934132710037826936173778980444968292764750946649017977"
    "587207096330286416692887910946555547851940402630657488671505820681908902000708383676273854845"
    "817711531764475730270069855571366959622842914819860834936475292719074168444365510704342711559"
    "699508093042880177904174497792";

static void nelf__json_ws(nelf__json *j) {
    while (j->p < j->end && (*j->p == ' ' || *j->p == '\n' || *j->p == '\t' || *j->p == '\r')) j->p++;
}

static int nelf__json_fail(nelf__json *j, const char *why) {
    j->error = why;
    return 0;
}

static int nelf__json_hex4(nelf__json *j, unsigned *out) {
    unsigned v = 0;
    int i;
    if (j->end - j->p < 4) return nelf__json_fail(j, "EOF in a hex escape");
    for (i = 0; i < 4; i++) {
        unsigned char c = *j->p++;
        unsigned d;
        if (c >= '0' && c <= '9') d = c - '0';
        else if (c >= 'a' && c <= 'f') d = c - 'a' + 10;
        else if (c >= 'A' && c <= 'F') d = c - 'A' + 10;
        else return nelf__json_fail(j, "invalid hex escape");
        v = v * 16 + d;
    }
    *out = v;
    return 1;
}

static int nelf__json_string(nelf__json *j) {
    j->p++; /* opening quote */
    for (;;) {
        unsigned char c;
        if (j->p >= j->end) return nelf__json_fail(j, "EOF while parsing a string");
        c = *j->p;
        if (c == '"') {
            j->p++;
            return 1;
        }
        if (c == '\\') {
            unsigned u, u2;
            j->p++;
            if (j->p >= j->end) return nelf__json_fail(j, "EOF while parsing a string");
            c = *j->p++;
            switch (c) {
            case '"': case '\\': case '/': case 'b': case 'f': case 'n': case 'r': case 't':
                break;
            case 'u':
                if (!nelf__json_hex4(j, &u)) return 0;
                if (u >= 0xDC00 && u <= 0xDFFF) return nelf__json_fail(j, "lone surrogate in a hex escape");
                if (u >= 0xD800 && u <= 0xDBFF) {
                    if (j->end - j->p < 2 || j->p[0] != '\\' || j->p[1] != 'u')
                        return nelf__json_fail(j, "unpaired surrogate in a hex escape");
                    j->p += 2;
                    if (!nelf__json_hex4(j, &u2)) return 0;
                    if (u2 < 0xDC00 || u2 > 0xDFFF) return nelf__json_fail(j, "lone surrogate in a hex escape");
                }
                break;
            default:
                return nelf__json_fail(j, "invalid escape");
            }
            continue;
        }
        if (c < 0x20) return nelf__json_fail(j, "control character in a string");
        if (c < 0x80) {
            j->p++;
            continue;
        }
        { /* UTF-8 sequence, validated as Rust's str::from_utf8 does */
            size_t need, k;
            unsigned char lo = 0x80, hi = 0xBF;
            if (c >= 0xC2 && c <= 0xDF) need = 1;
            else if (c >= 0xE0 && c <= 0xEF) {
                need = 2;
                if (c == 0xE0) lo = 0xA0;
                if (c == 0xED) hi = 0x9F;
            } else if (c >= 0xF0 && c <= 0xF4) {
                need = 3;
                if (c == 0xF0) lo = 0x90;
                if (c == 0xF4) hi = 0x8F;
            } else return nelf__json_fail(j, "invalid UTF-8 in a string");
            if ((size_t)(j->end - j->p) < need + 1) return nelf__json_fail(j, "invalid UTF-8 in a string");
            for (k = 1; k <= need; k++) {
                unsigned char cc = j->p[k];
                unsigned char l = k == 1 ? lo : 0x80, h = k == 1 ? hi : 0xBF;
                if (cc < l || cc > h) return nelf__json_fail(j, "invalid UTF-8 in a string");
            }
            j->p += need + 1;
        }
    }
}

static int nelf__json_digit(const nelf__json *j) { return j->p < j->end && *j->p >= '0' && *j->p <= '9'; }

static int nelf__json_number(nelf__json *j) {
    const unsigned char *int_start, *int_end, *frac_start = NULL, *frac_end = NULL;
    int64_t exponent = 0, intdigits, first = -1, position, i;
    int exp_negative = 0;
    if (*j->p == '-') j->p++;
    if (j->p >= j->end) return nelf__json_fail(j, "EOF in a number");
    int_start = j->p;
    if (*j->p == '0') {
        j->p++;
        if (nelf__json_digit(j)) return nelf__json_fail(j, "leading zero in a number");
    } else if (*j->p >= '1' && *j->p <= '9') {
        while (nelf__json_digit(j)) j->p++;
    } else {
        return nelf__json_fail(j, "invalid number");
    }
    int_end = j->p;
    if (j->p < j->end && *j->p == '.') {
        j->p++;
        frac_start = j->p;
        while (nelf__json_digit(j)) j->p++;
        frac_end = j->p;
        if (frac_end == frac_start) return nelf__json_fail(j, "no digit after the decimal point");
    }
    if (j->p < j->end && (*j->p == 'e' || *j->p == 'E')) {
        j->p++;
        if (j->p < j->end && (*j->p == '+' || *j->p == '-')) exp_negative = *j->p++ == '-';
        if (!nelf__json_digit(j)) return nelf__json_fail(j, "no digit in an exponent");
        while (nelf__json_digit(j)) {
            if (exponent < 1000000000) exponent = exponent * 10 + (*j->p - '0');
            j->p++;
        }
        if (exp_negative) exponent = -exponent;
    }
    /* Magnitude check: value = 0.d_first d_... x 10^(intdigits - first + exponent). */
    intdigits = int_end - int_start;
    {
        int64_t total = intdigits + (frac_start ? frac_end - frac_start : 0);
        for (i = 0; i < total; i++) {
            unsigned char d = i < intdigits ? int_start[i] : frac_start[i - intdigits];
            if (d != '0') {
                first = i;
                break;
            }
        }
        if (first < 0) return 1; /* zero */
        position = intdigits - first + exponent;
        if (position < 309) return 1;
        if (position > 309) return nelf__json_fail(j, "number out of range");
        for (i = 0; i < 309; i++) {
            int64_t at = first + i;
            unsigned char d = at < total ? (at < intdigits ? int_start[at] : frac_start[at - intdigits]) : '0';
            if (d < (unsigned char)nelf__json_inf_digits[i]) return 1;
            if (d > (unsigned char)nelf__json_inf_digits[i]) return nelf__json_fail(j, "number out of range");
        }
        return nelf__json_fail(j, "number out of range"); /* >= the threshold */
    }
}

static int nelf__json_literal(nelf__json *j, const char *word) {
    size_t n = strlen(word);
    if ((size_t)(j->end - j->p) < n || memcmp(j->p, word, n) != 0) return nelf__json_fail(j, "expected a value");
    j->p += n;
    return 1;
}

static int nelf__json_value(nelf__json *j) {
    if (j->p >= j->end) return nelf__json_fail(j, "EOF while parsing a value");
    switch (*j->p) {
    case '{':
        if (--j->remaining_depth == 0) return nelf__json_fail(j, "recursion limit exceeded");
        j->p++;
        nelf__json_ws(j);
        if (j->p < j->end && *j->p == '}') {
            j->p++;
        } else {
            for (;;) {
                nelf__json_ws(j);
                if (j->p >= j->end || *j->p != '"') return nelf__json_fail(j, "expected a string key");
                if (!nelf__json_string(j)) return 0;
                nelf__json_ws(j);
                if (j->p >= j->end || *j->p != ':') return nelf__json_fail(j, "expected ':'");
                j->p++;
                nelf__json_ws(j);
                if (!nelf__json_value(j)) return 0;
                nelf__json_ws(j);
                if (j->p < j->end && *j->p == ',') {
                    j->p++;
                    continue;
                }
                if (j->p < j->end && *j->p == '}') {
                    j->p++;
                    break;
                }
                return nelf__json_fail(j, "expected ',' or '}'");
            }
        }
        j->remaining_depth++;
        return 1;
    case '[':
        if (--j->remaining_depth == 0) return nelf__json_fail(j, "recursion limit exceeded");
        j->p++;
        nelf__json_ws(j);
        if (j->p < j->end && *j->p == ']') {
            j->p++;
        } else {
            for (;;) {
                nelf__json_ws(j);
                if (!nelf__json_value(j)) return 0;
                nelf__json_ws(j);
                if (j->p < j->end && *j->p == ',') {
                    j->p++;
                    continue;
                }
                if (j->p < j->end && *j->p == ']') {
                    j->p++;
                    break;
                }
                return nelf__json_fail(j, "expected ',' or ']'");
            }
        }
        j->remaining_depth++;
        return 1;
    case '"':
        return nelf__json_string(j);
    case 't':
        return nelf__json_literal(j, "true");
    case 'f':
        return nelf__json_literal(j, "false");
    case 'n':
        return nelf__json_literal(j, "null");
    default:
        if (*j->p == '-' || (*j->p >= '0' && *j->p <= '9')) return nelf__json_number(j);
        return nelf__json_fail(j, "expected a value");
    }
}

static nelf_result nelf__check_metadata(nelf_reader *r, const unsigned char *text, size_t length) {
    nelf__json j;
    int is_object;
    j.p = text;
    j.end = text + length;
    j.remaining_depth = 128;
    j.error = NULL;
    nelf__json_ws(&j);
    is_object = j.p < j.end && *j.p == '{';
    if (!nelf__json_value(&j))
        return nelf__fail(r, NELF_ERR_METADATA_JSON, "metadata JSON: %s at byte %llu", j.error,
                          (unsigned long long)(j.p - text));
    nelf__json_ws(&j);
    if (j.p != j.end)
        return nelf__fail(r, NELF_ERR_METADATA_JSON, "metadata JSON: trailing characters at byte %llu",
                          (unsigned long long)(j.p - text));
    if (!is_object) return nelf__fail(r, NELF_ERR_METADATA_NOT_OBJECT, "metadata must be a JSON object");
    return NELF_OK;
}

/* ---------------------------------------------------------------- header */

static uint64_t nelf__coef_bytes_per_brick(const nelf_header *h) {
    return (uint64_t)NELF_BRICK_VOXELS * h->pca_rank * (h->coefficient_encoding == NELF_ENCODING_F16 ? 2u : 1u);
}

/* Decoded bytes of one brick of DNSF: 2 x 512 F^3 (0 without a fine density). */
static uint64_t nelf__fine_bytes_per_brick(const nelf_header *h) {
    uint64_t f = h->fine_density_factor;
    return 2u * NELF_BRICK_VOXELS * f * f * f;
}

static uint64_t nelf__bricks_in_chunk(const nelf_header *h, uint64_t chunk) {
    uint64_t start = chunk * h->chunk_bricks, b = h->brick_count;
    uint64_t left = b - (start < b ? start : b);
    return left < h->chunk_bricks ? left : h->chunk_bricks;
}

/* Whether the row-major m is a proper rotation to `tol`, computed as glam does
 * (MᵀM element by element, det = c0 . (c1 x c2) with c the columns). */
static int nelf__is_rotation(const double *m, double tol) {
    int a, b;
    double cx[3], det;
    for (a = 0; a < 3; a++) {
        for (b = 0; b < 3; b++) {
            double g = m[a] * m[b] + m[3 + a] * m[3 + b];
            g = g + m[6 + a] * m[6 + b];
            if (!(nelf__abs(g - (a == b ? 1.0 : 0.0)) <= tol)) return 0;
        }
    }
    /* columns c0 = (m0, m3, m6), c1 = (m1, m4, m7), c2 = (m2, m5, m8) */
    cx[0] = m[4] * m[8] - m[7] * m[5];
    cx[1] = m[7] * m[2] - m[8] * m[1];
    cx[2] = m[1] * m[5] - m[2] * m[4];
    det = m[0] * cx[0] + m[3] * cx[1];
    det = det + m[6] * cx[2];
    return nelf__abs(det - 1.0) < tol;
}

static nelf_result nelf__parse_header(nelf_reader *r, const unsigned char *b, uint64_t have) {
    static const unsigned char magic[8] = {0x89, 'N', 'E', 'L', 'F', 0x0D, 0x0A, 0x1A};
    nelf_header *h = &r->header;
    uint64_t table_end, flags, chunk_raw, per_brick;
    int a;
    if (have >= 8 && memcmp(b, magic, 8) != 0)
        return nelf__fail(r, NELF_ERR_BAD_MAGIC,
                          "not a .nelf file: bad magic [%02x, %02x, %02x, %02x, %02x, %02x, %02x, %02x]", b[0], b[1],
                          b[2], b[3], b[4], b[5], b[6], b[7]);
    if (have < NELF_HEADER_SIZE)
        return nelf__fail(r, NELF_ERR_TRUNCATED, "truncated file: header needs 256 bytes but only %llu are there",
                          (unsigned long long)have);
    memset(h, 0, sizeof *h);
    h->version_major = nelf__u16(b + 8);
    h->version_minor = nelf__u16(b + 10);
    if (h->version_major != NELF_VERSION_MAJOR)
        return nelf__fail(r, NELF_ERR_UNSUPPORTED_VERSION,
                          "unsupported .nelf version %u.%u (this reader reads major version 1)", h->version_major,
                          h->version_minor);
    h->header_size = nelf__u32(b + 12);
    if (h->header_size != NELF_HEADER_SIZE)
        return nelf__fail(r, NELF_ERR_HEADER_SIZE, "invalid header field header_size: %lu, must be 256",
                          (unsigned long)h->header_size);
    h->section_entry_size = nelf__u32(b + 20);
    if (h->section_entry_size != NELF_SECTION_ENTRY_SIZE)
        return nelf__fail(r, NELF_ERR_SECTION_ENTRY_SIZE, "invalid header field section_entry_size: %lu, must be 48",
                          (unsigned long)h->section_entry_size);
    h->file_size = nelf__u64(b + 200);
    if (h->file_size != r->file_size) {
        if (r->file_size < h->file_size)
            return nelf__fail(r, NELF_ERR_TRUNCATED, "truncated file: file needs %llu bytes but only %llu are there",
                              (unsigned long long)h->file_size, (unsigned long long)r->file_size);
        return nelf__fail(r, NELF_ERR_FILE_SIZE_MISMATCH,
                          "file is %llu bytes but its header says %llu (truncated or appended to)",
                          (unsigned long long)r->file_size, (unsigned long long)h->file_size);
    }
    h->section_count = nelf__u32(b + 16);
    if (h->section_count > NELF_MAX_SECTIONS)
        return nelf__fail(r, NELF_ERR_TOO_MANY_SECTIONS, "section table declares %lu sections (at most 64)",
                          (unsigned long)h->section_count);
    table_end = NELF_HEADER_SIZE + (uint64_t)h->section_count * NELF_SECTION_ENTRY_SIZE;
    if (table_end > h->file_size)
        return nelf__fail(r, NELF_ERR_TRUNCATED,
                          "truncated file: section table needs %llu bytes but only %llu are there",
                          (unsigned long long)table_end, (unsigned long long)h->file_size);
    flags = nelf__u64(b + 24);
    h->flags = flags;
    if (flags & 0xFFFFFFFFull & ~(uint64_t)NELF_FLAG_SIGNED_DENSITY)
        return nelf__fail(r, NELF_ERR_UNSUPPORTED_FEATURE, "file requires unknown feature flags 0x%llx",
                          (unsigned long long)(flags & 0xFFFFFFFFull & ~(uint64_t)NELF_FLAG_SIGNED_DENSITY));
    for (a = 0; a < 3; a++) h->bbox_min_m[a] = nelf__f64(b + 32 + 8 * a);
    for (a = 0; a < 3; a++) h->bbox_max_m[a] = nelf__f64(b + 56 + 8 * a);
    h->voxel_size_m = nelf__f64(b + 80);
    for (a = 0; a < 3; a++)
        if (!nelf__finite64(h->bbox_min_m[a]))
            return nelf__fail(r, NELF_ERR_NONFINITE_HEADER, "non-finite value in header field bbox_min");
    for (a = 0; a < 3; a++)
        if (!nelf__finite64(h->bbox_max_m[a]))
            return nelf__fail(r, NELF_ERR_NONFINITE_HEADER, "non-finite value in header field bbox_max");
    if (!nelf__finite64(h->voxel_size_m))
        return nelf__fail(r, NELF_ERR_NONFINITE_HEADER, "non-finite value in header field voxel_size");
    for (a = 0; a < 3; a++) h->grid_bricks[a] = nelf__u32(b + 88 + 4 * a);
    /* The grid: positive voxel size, extents in 1..=65536, finite maximum corner. */
    if (!(h->voxel_size_m > 0.0))
        return nelf__fail(r, NELF_ERR_GRID, "invalid header field grid: voxel size %.17g must be positive and finite",
                          h->voxel_size_m);
    for (a = 0; a < 3; a++)
        if (h->grid_bricks[a] == 0 || h->grid_bricks[a] > NELF__MAX_GRID_BRICKS)
            return nelf__fail(r, NELF_ERR_GRID,
                              "invalid header field grid: grid extent [%lu, %lu, %lu] bricks must be in 1..=65536 per axis",
                              (unsigned long)h->grid_bricks[0], (unsigned long)h->grid_bricks[1],
                              (unsigned long)h->grid_bricks[2]);
    {
        double expected[3];
        for (a = 0; a < 3; a++) {
            expected[a] = h->bbox_min_m[a] + ((double)h->grid_bricks[a] * 8.0) * h->voxel_size_m;
            if (!nelf__finite64(expected[a]))
                return nelf__fail(r, NELF_ERR_GRID, "invalid header field grid: grid box maximum overflows");
        }
        for (a = 0; a < 3; a++) {
            double extent = expected[a] - h->bbox_min_m[a];
            double tol = 1e-6 * (nelf__abs(extent) + nelf__abs(h->bbox_min_m[a])) + 1e-12;
            if (nelf__abs(h->bbox_max_m[a] - expected[a]) > tol)
                return nelf__fail(r, NELF_ERR_BBOX_MAX,
                                  "invalid header field bbox_max: axis %d is %.17g, bbox_min + 8 grid_bricks voxel_size = %.17g",
                                  a, h->bbox_max_m[a], expected[a]);
        }
    }
    h->brick_size = nelf__u32(b + 100);
    if (h->brick_size != NELF_BRICK_SIZE)
        return nelf__fail(r, NELF_ERR_BRICK_SIZE, "invalid header field brick_size: %lu, must be 8",
                          (unsigned long)h->brick_size);
    h->brick_count = nelf__u32(b + 104);
    h->chunk_bricks = nelf__u32(b + 108);
    for (a = 0; a < 9; a++) h->world_from_light[a] = nelf__f64(b + 112 + 8 * a);
    for (a = 0; a < 9; a++)
        if (!nelf__finite64(h->world_from_light[a]))
            return nelf__fail(r, NELF_ERR_NONFINITE_HEADER, "non-finite value in header field world_from_light");
    if (!nelf__is_rotation(h->world_from_light, 1e-5))
        return nelf__fail(r, NELF_ERR_NOT_A_ROTATION, "invalid header field world_from_light: not a rotation (to 1e-5)");
    h->env_height = nelf__u16(b + 184);
    h->env_width = nelf__u16(b + 186);
    if (h->env_height != NELF_ENV_HEIGHT || h->env_width != NELF_ENV_WIDTH)
        return nelf__fail(r, NELF_ERR_ENV_SIZE, "invalid header field env_size: %ux%u, v1 requires 8x16",
                          h->env_height, h->env_width);
    h->pca_rank = nelf__u32(b + 188);
    if (h->pca_rank == 0 || h->pca_rank > NELF_MAX_RANK)
        return nelf__fail(r, NELF_ERR_BAD_RANK, "PCA rank %lu is outside 1..=384", (unsigned long)h->pca_rank);
    h->coefficient_encoding = nelf__u32(b + 192);
    if (h->coefficient_encoding != NELF_ENCODING_U8_AFFINE && h->coefficient_encoding != NELF_ENCODING_F16)
        return nelf__fail(r, NELF_ERR_BAD_ENCODING, "invalid header field coefficient_encoding: unknown encoding %lu",
                          (unsigned long)h->coefficient_encoding);
    /* Reserved before 1.4 (written 0), so an older file reads as factor 0. */
    h->fine_density_factor = nelf__u32(b + 196);
    if (h->fine_density_factor != 0 && h->fine_density_factor != 2 && h->fine_density_factor != 4)
        return nelf__fail(r, NELF_ERR_FINE_DENSITY_FACTOR,
                          "invalid header field fine_density_factor: %lu, must be 0 (none), 2 or 4",
                          (unsigned long)h->fine_density_factor);
    if (h->chunk_bricks == 0)
        return nelf__fail(r, NELF_ERR_CHUNK_BRICKS, "invalid header field chunk_bricks: 0, must be at least 1");
    per_brick = nelf__coef_bytes_per_brick(h);
    if (per_brick < 2u * NELF_BRICK_VOXELS) per_brick = 2u * NELF_BRICK_VOXELS;
    if (per_brick < nelf__fine_bytes_per_brick(h)) per_brick = nelf__fine_bytes_per_brick(h);
    chunk_raw = (uint64_t)h->chunk_bricks * per_brick;
    if (chunk_raw > NELF__MAX_CHUNK_RAW_BYTES)
        return nelf__fail(r, NELF_ERR_CHUNK_TOO_LARGE,
                          "chunk_bricks x bytes per brick = %llu is too large (limit 4194304)",
                          (unsigned long long)chunk_raw);
    h->header_checksum = nelf__u64(b + 248);
    return NELF_OK;
}

/* ---------------------------------------------------------------- section table */

static int nelf__known_kind(const char kind[4]) {
    int k;
    for (k = 0; k < NELF__KNOWN; k++)
        if (memcmp(kind, nelf__kinds[k], 4) == 0) return k;
    return -1;
}

static uint64_t nelf__expected_raw(const nelf_header *h, int kind) {
    uint64_t bricks = h->brick_count, rank = h->pca_rank;
    switch (kind) {
    case NELF__BRCK: return 6 * bricks;
    case NELF__PCAB: return 4u * NELF_LT_DIM * (rank + 1);
    case NELF__QPRM: return 8 * rank;
    default: return UINT64_MAX; /* metadata, VDEP, VREF: variable */
    }
}

/* Checks a chunked section's entry (DENS, DNSF, COEF, VCOF, VRCO) whose bricks decode to `per_brick`
 * bytes: decoded length B x per_brick, shuffle dividing a brick, a chunk <= 4 MiB. */
static nelf_result nelf__check_chunked_entry(nelf_reader *r, const nelf_section *s, uint64_t per_brick) {
    const nelf_header *h = &r->header;
    uint64_t width = s->shuffle, expected = per_brick * h->brick_count;
    char name[17];
    nelf__kind_text(s->kind, name);
    if (expected != s->raw_length)
        return nelf__fail(r, NELF_ERR_SECTION_LENGTH,
                          "section %s declares %llu decoded bytes but the header's counts need %llu", name,
                          (unsigned long long)s->raw_length, (unsigned long long)expected);
    if (width > 1 && per_brick % width != 0)
        return nelf__fail(r, NELF_ERR_BAD_CODEC, "section %s: shuffle width %llu does not divide the %llu bytes of a brick",
                          name, (unsigned long long)width, (unsigned long long)per_brick);
    if ((uint64_t)h->chunk_bricks * per_brick > NELF__MAX_CHUNK_RAW_BYTES)
        return nelf__fail(r, NELF_ERR_CHUNK_TOO_LARGE, "section %s chunk decoded bytes = %llu is too large (limit 4194304)",
                          name, (unsigned long long)((uint64_t)h->chunk_bricks * per_brick));
    return NELF_OK;
}

static nelf_result nelf__check_entry(nelf_reader *r, const nelf_section *s, int kind) {
    const nelf_header *h = &r->header;
    char name[17];
    int chunked = kind == NELF__DENS || kind == NELF__DNSF || kind == NELF__COEF || kind == NELF__VCOF ||
                  kind == NELF__VRCO;
    uint64_t width = s->shuffle;
    nelf__kind_text(s->kind, name);
    if (!((s->codec == 0 && !chunked) || (s->codec == 2 && chunked) || (s->codec == 1 && !chunked && kind != NELF__BRCK)))
        return nelf__fail(r, NELF_ERR_BAD_CODEC, "section %s: codec %u is not allowed for this section", name, s->codec);
    if (kind == NELF__DENS) return nelf__check_chunked_entry(r, s, 2u * NELF_BRICK_VOXELS);
    /* nelf__check_table checked that the factor is not 0 when DNSF is present. */
    if (kind == NELF__DNSF) return nelf__check_chunked_entry(r, s, nelf__fine_bytes_per_brick(h));
    if (kind == NELF__COEF) return nelf__check_chunked_entry(r, s, nelf__coef_bytes_per_brick(h));
    if (kind == NELF__VCOF) return NELF_OK; /* checked once VDEP gives its brick size */
    if (kind == NELF__VRCO) return nelf__check_chunked_entry(r, s, NELF__REFLECTION_BYTES_PER_BRICK);
    if (kind == NELF__META) {
        if (s->raw_length > NELF__MAX_METADATA_BYTES)
            return nelf__fail(r, NELF_ERR_METADATA_TOO_LARGE,
                              "section %s decoded length = %llu is too large (limit 1048576)", name,
                              (unsigned long long)s->raw_length);
    } else if (kind == NELF__VDEP) {
        if (s->raw_length > NELF__MAX_VIEW_PARAMS_BYTES)
            return nelf__fail(r, NELF_ERR_BAD_VIEW,
                              "invalid view-dependent part: section VDEP declares %llu decoded bytes, more than the largest possible %llu",
                              (unsigned long long)s->raw_length, (unsigned long long)NELF__MAX_VIEW_PARAMS_BYTES);
    } else if (kind == NELF__VREF) {
        /* 32 + 12 E bytes for 1..16 eyes; the eye count itself is checked once it is read. */
        uint64_t extra = s->raw_length - 32u;
        if (s->raw_length < NELF__REFLECTION_PARAMS_BYTES(1) ||
            s->raw_length > NELF__REFLECTION_PARAMS_BYTES(NELF_MAX_REFLECTION_EYES) || extra % 12u != 0)
            return nelf__fail(r, NELF_ERR_BAD_VIEW,
                              "invalid view-dependent part: section VREF declares %llu decoded bytes, which is not 32 + 12 x (1..=%d eyes)",
                              (unsigned long long)s->raw_length, NELF_MAX_REFLECTION_EYES);
    } else {
        uint64_t expected = nelf__expected_raw(h, kind);
        if (expected != s->raw_length)
            return nelf__fail(r, NELF_ERR_SECTION_LENGTH,
                              "section %s declares %llu decoded bytes but the header's counts need %llu", name,
                              (unsigned long long)s->raw_length, (unsigned long long)expected);
    }
    if (s->codec == 0) {
        if (s->shuffle != 0)
            return nelf__fail(r, NELF_ERR_BAD_CODEC, "section %s: raw section with shuffle width %lu", name,
                              (unsigned long)s->shuffle);
        if (s->stored_length != s->raw_length)
            return nelf__fail(r, NELF_ERR_BAD_CODEC, "section %s: raw section stores %llu bytes but declares %llu decoded",
                              name, (unsigned long long)s->stored_length, (unsigned long long)s->raw_length);
    } else if (s->codec == 1) {
        if (width > 1 && s->raw_length % width != 0)
            return nelf__fail(r, NELF_ERR_BAD_CODEC, "section %s: shuffle width %llu does not divide decoded length %llu",
                              name, (unsigned long long)width, (unsigned long long)s->raw_length);
        if (s->raw_length > nelf__sat_mul(s->stored_length, NELF__MAX_ZSTD_EXPANSION))
            return nelf__fail(r, NELF_ERR_IMPLAUSIBLE_LENGTH,
                              "section %s: declared decoded length %llu is implausible for %llu stored bytes", name,
                              (unsigned long long)s->raw_length, (unsigned long long)s->stored_length);
    }
    return NELF_OK;
}

static nelf_result nelf__check_table(nelf_reader *r) {
    const nelf_header *h = &r->header;
    uint64_t data_start = NELF_HEADER_SIZE + (uint64_t)h->section_count * NELF_SECTION_ENTRY_SIZE;
    uint32_t n = h->section_count, i, k;
    int order[NELF_MAX_SECTIONS];
    char name[17], other[17];
    nelf_result rc;
    for (i = 0; i < n; i++) {
        const nelf_section *s = &r->sections[i];
        nelf__kind_text(s->kind, name);
        if (s->offset % 8 != 0)
            return nelf__fail(r, NELF_ERR_MISALIGNED, "section %s offset %llu is not 8-byte aligned", name,
                              (unsigned long long)s->offset);
        if (s->offset < data_start || s->stored_length > UINT64_MAX - s->offset ||
            s->offset + s->stored_length > h->file_size)
            return nelf__fail(r, NELF_ERR_SECTION_OUT_OF_BOUNDS,
                              "section %s at offset %llu with length %llu lies outside the data area [%llu, %llu)", name,
                              (unsigned long long)s->offset, (unsigned long long)s->stored_length,
                              (unsigned long long)data_start, (unsigned long long)h->file_size);
        for (k = 0; k < i; k++)
            if (memcmp(r->sections[k].kind, s->kind, 4) == 0)
                return nelf__fail(r, NELF_ERR_DUPLICATE_SECTION, "section %s appears more than once", name);
    }
    /* Stable sort by (offset, stored_length), then neighbours must not overlap. */
    for (i = 0; i < n; i++) {
        int cur = (int)i;
        k = i;
        while (k > 0) {
            const nelf_section *a = &r->sections[order[k - 1]], *b = &r->sections[cur];
            if (a->offset < b->offset || (a->offset == b->offset && a->stored_length <= b->stored_length)) break;
            order[k] = order[k - 1];
            k--;
        }
        order[k] = cur;
    }
    for (i = 0; i + 1 < n; i++) {
        const nelf_section *a = &r->sections[order[i]], *b = &r->sections[order[i + 1]];
        if (a->offset + a->stored_length > b->offset)
            return nelf__fail(r, NELF_ERR_SECTIONS_OVERLAP, "sections %s and %s overlap", nelf__kind_text(a->kind, name),
                              nelf__kind_text(b->kind, other));
    }
    /* The fine density (1.4) is there exactly when the header declares its factor. */
    {
        int has_fine = 0;
        for (i = 0; i < n; i++)
            if (memcmp(r->sections[i].kind, nelf__kinds[NELF__DNSF], 4) == 0) has_fine = 1;
        if (h->fine_density_factor == 0 && has_fine)
            return nelf__fail(r, NELF_ERR_FINE_DENSITY_FACTOR,
                              "invalid header field fine_density_factor: 0, but section DNSF is present");
        if (h->fine_density_factor != 0 && !has_fine)
            return nelf__fail(r, NELF_ERR_MISSING_SECTION, "required section DNSF is missing");
    }
    for (i = 0; i < NELF__KNOWN; i++) r->known[i] = -1;
    for (i = 0; i < n; i++) {
        const nelf_section *s = &r->sections[i];
        int kind = nelf__known_kind(s->kind);
        if (kind < 0) {
            if (s->flags & 1u)
                return nelf__fail(r, NELF_ERR_UNKNOWN_REQUIRED_SECTION,
                                  "unknown required section %s (written by a newer writer?)", nelf__kind_text(s->kind, name));
            continue;
        }
        r->known[kind] = (int)i;
        if ((rc = nelf__check_entry(r, s, kind)) != NELF_OK) return rc;
    }
    {
        static const int required[4] = {NELF__BRCK, NELF__DENS, NELF__PCAB, NELF__COEF};
        for (i = 0; i < 4; i++)
            if (r->known[required[i]] < 0)
                return nelf__fail(r, NELF_ERR_MISSING_SECTION, "required section %s is missing", nelf__kinds[required[i]]);
    }
    /* A view-dependent part is optional, but whole; and a file holds at most one. */
    if (r->known[NELF__VDEP] >= 0 && r->known[NELF__VREF] >= 0)
        return nelf__fail(r, NELF_ERR_BAD_VIEW,
                          "invalid view-dependent part: sections VDEP and VREF are both present: a file holds at most one view-dependent part");
    {
        static const int pairs[4][2] = {
            {NELF__VDEP, NELF__VCOF}, {NELF__VCOF, NELF__VDEP}, {NELF__VREF, NELF__VRCO}, {NELF__VRCO, NELF__VREF}};
        for (i = 0; i < 4; i++)
            if (r->known[pairs[i][0]] >= 0 && r->known[pairs[i][1]] < 0)
                return nelf__fail(r, NELF_ERR_BAD_VIEW, "invalid view-dependent part: section %s is present without section %s",
                                  nelf__kinds[pairs[i][0]], nelf__kinds[pairs[i][1]]);
    }
    r->has_view = r->known[NELF__VDEP] >= 0;
    r->has_reflection = r->known[NELF__VREF] >= 0;
    r->chunked_kind[0] = NELF__DENS;
    r->chunked_kind[1] = NELF__COEF;
    r->chunked = 2;
    if (r->has_view || r->has_reflection) r->chunked_kind[r->chunked++] = r->has_view ? NELF__VCOF : NELF__VRCO;
    r->fine_slot = -1;
    r->fine_voxels = 0;
    if (r->known[NELF__DNSF] >= 0) {
        r->fine_slot = r->chunked;
        r->fine_voxels = nelf__fine_bytes_per_brick(h) / 2u;
        r->chunked_kind[r->chunked++] = NELF__DNSF;
    }
    return NELF_OK;
}

/* Reads, checksums and decodes a whole (non-chunked) section into a new buffer. */
static nelf_result nelf__whole_section(nelf_reader *r, const nelf_section *s, unsigned char **out) {
    const unsigned char *stored;
    unsigned char *raw = NULL;
    size_t cap = 0;
    uint64_t computed;
    char what[32], name[17];
    nelf_result rc;
    *out = NULL;
    snprintf(what, sizeof what, "section %s", nelf__kind_text(s->kind, name));
    if ((rc = nelf__view(r, s->offset, s->stored_length, &stored, what)) != NELF_OK) return rc;
    computed = XXH3_64bits(stored, (size_t)s->stored_length);
    if (nelf__checksums_differ(s->checksum, computed))
        return nelf__fail(r, NELF_ERR_SECTION_CHECKSUM, "checksum mismatch in %s: stored 0x%016llx, computed 0x%016llx",
                          what, (unsigned long long)s->checksum, (unsigned long long)computed);
    /* raw_length is bounded: by the file (raw) or by the kind's limit (zstd). */
    if ((rc = nelf__reserve(r, &raw, &cap, s->raw_length)) != NELF_OK) return rc;
    if (s->codec == 0) {
        if (s->raw_length) memcpy(raw, stored, (size_t)s->raw_length);
    } else if ((rc = nelf__decode(r, stored, s->stored_length, raw, s->raw_length, s->shuffle, what)) != NELF_OK) {
        NELF_FREE(raw);
        return rc;
    }
    *out = raw;
    return NELF_OK;
}

/* Reads and checks the chunk table at the start of chunked section `which` (DENS, COEF,
 * then VCOF or VRCO, then DNSF). */
static nelf_result nelf__chunk_table(nelf_reader *r, int which) {
    const nelf_header *h = &r->header;
    const nelf_section *s = &r->sections[r->known[r->chunked_kind[which]]];
    const unsigned char *view;
    uint64_t count = r->chunk_count, table_length = count * NELF__CHUNK_ENTRY_SIZE, expected, i;
    size_t cap = 0;
    char name[17];
    nelf_result rc;
    nelf__kind_text(s->kind, name);
    if (table_length > s->stored_length)
        return nelf__fail(r, NELF_ERR_CHUNK_COUNT,
                          "chunks in section %s = %llu is too large (limit %llu)", name, (unsigned long long)count,
                          (unsigned long long)(s->stored_length / NELF__CHUNK_ENTRY_SIZE));
    if ((rc = nelf__view(r, s->offset, table_length, &view, "a chunk table")) != NELF_OK) return rc;
    if ((rc = nelf__reserve(r, &r->chunk_table[which], &cap, table_length)) != NELF_OK) return rc;
    if (table_length) memcpy(r->chunk_table[which], view, (size_t)table_length);
    expected = table_length;
    for (i = 0; i < count; i++) {
        const unsigned char *e = r->chunk_table[which] + i * NELF__CHUNK_ENTRY_SIZE;
        uint64_t offset = nelf__u64(e), length = nelf__u64(e + 8), raw;
        if (offset != expected)
            return nelf__fail(r, NELF_ERR_BAD_CHUNK_TABLE, "section %s: bad chunk table: chunk %llu starts at %llu, expected %llu",
                              name, (unsigned long long)i, (unsigned long long)offset, (unsigned long long)expected);
        if (length > UINT64_MAX - offset || offset + length > s->stored_length)
            return nelf__fail(r, NELF_ERR_BAD_CHUNK_TABLE,
                              "section %s: bad chunk table: chunk %llu (%llu bytes at %llu) runs past the section's %llu bytes",
                              name, (unsigned long long)i, (unsigned long long)length, (unsigned long long)offset,
                              (unsigned long long)s->stored_length);
        expected = offset + length;
        raw = nelf__bricks_in_chunk(h, i) * r->bytes_per_brick[which];
        if (raw > nelf__sat_mul(length, NELF__MAX_ZSTD_EXPANSION))
            return nelf__fail(r, NELF_ERR_IMPLAUSIBLE_LENGTH,
                              "section %s chunk %llu: declared decoded length %llu is implausible for %llu stored bytes",
                              name, (unsigned long long)i, (unsigned long long)raw, (unsigned long long)length);
    }
    if (expected != s->stored_length)
        return nelf__fail(r, NELF_ERR_BAD_CHUNK_TABLE, "section %s: bad chunk table: chunks end at %llu but the section is %llu bytes",
                          name, (unsigned long long)expected, (unsigned long long)s->stored_length);
    return NELF_OK;
}

/* Checks 8-bit dequantization parameters (QPRM, the end of VDEP or VREF) as the reference does:
 * scale, offset and offset + 255 scale finite, then scale >= 0 (-0 passes). */
static nelf_result nelf__check_qparams(nelf_reader *r, const float *scale, const float *offset, uint64_t count,
                                       const char *section) {
    uint64_t i;
    for (i = 0; i < count; i++) {
        float s = scale[i], o = offset[i];
        float top = o + 255.0f * s;
        if (!(nelf__finite32(s) && nelf__finite32(o) && nelf__finite32(top)))
            return nelf__fail(r, strcmp(section, "QPRM") == 0 ? NELF_ERR_NONFINITE_QPRM : NELF_ERR_NONFINITE_VIEW,
                              "non-finite value in section %s component %llu (scale %.9g, offset %.9g)", section,
                              (unsigned long long)i, (double)s, (double)o);
        if (s < 0.0f)
            return nelf__fail(r, NELF_ERR_NEGATIVE_SCALE, "invalid value in section %s component %llu: negative scale %.9g",
                              section, (unsigned long long)i, (double)s);
    }
    return NELF_OK;
}

/* Decodes VDEP (`length` bytes, SPEC.md section 6): u32 J, K_v, encoding, reserved; then
 * f32 lobes[J 9], basis[K_v 384] and, 8-bit, R (scale, offset) pairs; all checked. */
static nelf_result nelf__parse_view(nelf_reader *r, const unsigned char *bytes, uint64_t length) {
    uint64_t lobes, rank, per_voxel, expected, values, i, floats;
    uint32_t encoding;
    nelf_view *v = &r->view;
    if (length < NELF__VIEW_HEADER_SIZE)
        return nelf__fail(r, NELF_ERR_BAD_VIEW,
                          "invalid view-dependent part: section VDEP: %llu decoded bytes, shorter than its 16-byte header",
                          (unsigned long long)length);
    lobes = nelf__u32(bytes);
    rank = nelf__u32(bytes + 4);
    encoding = nelf__u32(bytes + 8);
    if (lobes == 0 || lobes > NELF_VIEW_HARMONICS)
        return nelf__fail(r, NELF_ERR_BAD_VIEW, "invalid view-dependent part: section VDEP: %llu lobes, must be 1 to %d",
                          (unsigned long long)lobes, NELF_VIEW_HARMONICS);
    per_voxel = lobes * rank;
    if (rank == 0 || per_voxel > NELF_LT_DIM)
        return nelf__fail(r, NELF_ERR_BAD_VIEW,
                          "invalid view-dependent part: section VDEP: %llu lobes x rank %llu = %llu coefficients per voxel, must be 1 to 384",
                          (unsigned long long)lobes, (unsigned long long)rank, (unsigned long long)per_voxel);
    if (encoding != NELF_ENCODING_U8_AFFINE && encoding != NELF_ENCODING_F16)
        return nelf__fail(r, NELF_ERR_BAD_VIEW, "invalid view-dependent part: section VDEP: unknown coefficient encoding %lu",
                          (unsigned long)encoding);
    values = NELF_VIEW_HARMONICS * lobes + (uint64_t)NELF_LT_DIM * rank;
    floats = values + (encoding == NELF_ENCODING_U8_AFFINE ? 2 * per_voxel : 0);
    expected = NELF__VIEW_HEADER_SIZE + 4 * floats;
    if (expected != length)
        return nelf__fail(r, NELF_ERR_BAD_VIEW,
                          "invalid view-dependent part: section VDEP: %llu decoded bytes, but %llu lobes x rank %llu with %s coefficients need %llu",
                          (unsigned long long)length, (unsigned long long)lobes, (unsigned long long)rank,
                          encoding == NELF_ENCODING_F16 ? "f16" : "u8-affine", (unsigned long long)expected);
    r->view_params = (float *)NELF_MALLOC((size_t)floats * sizeof(float));
    if (!r->view_params) return nelf__fail(r, NELF_ERR_OUT_OF_MEMORY, "out of memory for VDEP");
    for (i = 0; i < values; i++) r->view_params[i] = nelf__f32(bytes + NELF__VIEW_HEADER_SIZE + 4 * i);
    v->lobe_count = (uint32_t)lobes;
    v->rank = (uint32_t)rank;
    v->coefficients_per_voxel = (uint32_t)per_voxel;
    v->encoding = encoding;
    v->lobes = r->view_params;
    v->basis = r->view_params + NELF_VIEW_HARMONICS * lobes;
    v->scale = v->offset = NULL;
    for (i = 0; i < NELF_VIEW_HARMONICS * lobes; i++)
        if (!nelf__finite32(v->lobes[i]))
            return nelf__fail(r, NELF_ERR_NONFINITE_VIEW, "non-finite value in section VDEP lobe %llu weight %llu",
                              (unsigned long long)(i / NELF_VIEW_HARMONICS), (unsigned long long)(i % NELF_VIEW_HARMONICS));
    for (i = 0; i < (uint64_t)NELF_LT_DIM * rank; i++)
        if (!nelf__finite32(v->basis[i]))
            return nelf__fail(r, NELF_ERR_NONFINITE_VIEW, "non-finite value in section VDEP basis vector %llu element %llu",
                              (unsigned long long)(i / NELF_LT_DIM), (unsigned long long)(i % NELF_LT_DIM));
    if (encoding == NELF_ENCODING_U8_AFFINE) {
        float *scale = r->view_params + values, *offset = scale + per_voxel;
        const unsigned char *pairs = bytes + NELF__VIEW_HEADER_SIZE + 4 * values;
        for (i = 0; i < per_voxel; i++) {
            scale[i] = nelf__f32(pairs + 8 * i);
            offset[i] = nelf__f32(pairs + 8 * i + 4);
        }
        v->scale = scale;
        v->offset = offset;
        return nelf__check_qparams(r, scale, offset, per_voxel, "VDEP");
    }
    return NELF_OK;
}

/* Decodes VREF (`length` bytes, SPEC.md section 6): u32 E, f32 exponent, E eyes of 3 f32,
 * then 3 (scale, offset) f32 pairs; checked in the reference's order (eye count and length,
 * the parameters as QPRM's, the exponent, finite eyes, a non-negative offset of the scale). */
static nelf_result nelf__parse_reflection(nelf_reader *r, const unsigned char *bytes, uint64_t length) {
    nelf_reflection *part = &r->reflection;
    const unsigned char *pairs;
    uint64_t eyes;
    uint32_t e, k;
    nelf_result rc;
    if (length < 8)
        return nelf__fail(r, NELF_ERR_BAD_VIEW,
                          "invalid view-dependent part: section VREF: %llu bytes, fewer than its 8-byte start",
                          (unsigned long long)length);
    eyes = nelf__u32(bytes);
    if (eyes == 0 || eyes > NELF_MAX_REFLECTION_EYES || NELF__REFLECTION_PARAMS_BYTES(eyes) != length)
        return nelf__fail(r, NELF_ERR_BAD_VIEW,
                          "invalid view-dependent part: section VREF: %llu eyes do not fit its %llu bytes (32 + 12 per eye, 1..=%d eyes)",
                          (unsigned long long)eyes, (unsigned long long)length, NELF_MAX_REFLECTION_EYES);
    memset(part, 0, sizeof *part);
    part->eye_count = (uint32_t)eyes;
    part->exponent = nelf__f32(bytes + 4);
    for (e = 0; e < part->eye_count; e++)
        for (k = 0; k < 3; k++) part->eyes_m[e][k] = nelf__f32(bytes + 8 + 12 * e + 4 * k);
    pairs = bytes + 8 + 12 * eyes;
    for (k = 0; k < NELF_REFLECTION_VALUES; k++) {
        part->scale[k] = nelf__f32(pairs + 8 * k);
        part->offset[k] = nelf__f32(pairs + 8 * k + 4);
    }
    if ((rc = nelf__check_qparams(r, part->scale, part->offset, NELF_REFLECTION_VALUES, "VREF")) != NELF_OK) return rc;
    if (!(part->exponent >= 1.0f && part->exponent <= NELF_MAX_REFLECTION_EXPONENT))
        return nelf__fail(r, NELF_ERR_BAD_VIEW, "invalid view-dependent part: section VREF: lobe exponent %.9g is not in 1..=200",
                          (double)part->exponent);
    for (e = 0; e < part->eye_count; e++)
        for (k = 0; k < 3; k++)
            if (!nelf__finite32(part->eyes_m[e][k]))
                return nelf__fail(r, NELF_ERR_NONFINITE_VIEW, "non-finite value in section VREF eye %lu", (unsigned long)e);
    if (part->offset[2] < 0.0f)
        return nelf__fail(r, NELF_ERR_BAD_VIEW, "invalid view-dependent part: section VREF: the scale's offset %.9g is negative",
                          (double)part->offset[2]);
    return NELF_OK;
}

/* ---------------------------------------------------------------- open / close */

static void nelf__release(nelf_reader *r) {
    int i;
    if (r->file) fclose(r->file);
    r->file = NULL;
    r->mem = NULL;
    NELF_FREE(r->bricks);
    NELF_FREE(r->pca);
    NELF_FREE(r->qparams);
    NELF_FREE(r->meta);
    NELF_FREE(r->view_params);
    r->view_params = NULL;
    memset(&r->view, 0, sizeof r->view);
    r->has_view = 0;
    memset(&r->reflection, 0, sizeof r->reflection);
    r->has_reflection = 0;
    r->fine_slot = -1;
    r->fine_voxels = 0;
    r->chunked = 0;
    for (i = 0; i < NELF__CHUNKED; i++) {
        NELF_FREE(r->chunk_table[i]);
        NELF_FREE(r->raw[i]);
        r->chunk_table[i] = NULL;
        r->raw[i] = NULL;
        r->raw_cap[i] = 0;
    }
    NELF_FREE(r->io);
    NELF_FREE(r->tmp);
    NELF_FREE(r->brick_density);
    NELF_FREE(r->brick_coef);
    NELF_FREE(r->brick_view);
    r->brick_view = NULL;
    NELF_FREE(r->brick_reflection);
    r->brick_reflection = NULL;
    NELF_FREE(r->brick_fine_density);
    r->brick_fine_density = NULL;
    r->bricks = NULL;
    r->pca = NULL;
    r->qparams = NULL;
    r->meta = NULL;
    r->meta_length = 0;
    r->io = r->tmp = NULL;
    r->io_cap = r->tmp_cap = 0;
    r->brick_density = r->brick_coef = NULL;
    r->is_open = 0;
    r->cached_chunk = -1;
}

NELF_API nelf_reader *nelf_create(void) {
    nelf_reader *r = (nelf_reader *)NELF_MALLOC(sizeof *r);
    if (!r) return NULL;
    memset(r, 0, sizeof *r);
    r->cached_chunk = -1;
    r->fine_slot = -1;
    r->status = NELF_ERR_NOT_OPEN;
    return r;
}

NELF_API void nelf_destroy(nelf_reader *r) {
    if (!r) return;
    nelf__release(r);
    if (r->dctx) ZSTD_freeDCtx(r->dctx);
    NELF_FREE(r);
}

static nelf_result nelf__open(nelf_reader *r) {
    const nelf_header *h = &r->header;
    unsigned char head[NELF_HEADER_SIZE];
    unsigned char hashed[248 + NELF_MAX_SECTIONS * NELF_SECTION_ENTRY_SIZE];
    const unsigned char *view;
    uint64_t have = r->file_size < NELF_HEADER_SIZE ? r->file_size : NELF_HEADER_SIZE, computed, i, count, rank;
    unsigned char *bytes = NULL;
    nelf_result rc;
    if (!r->dctx && !(r->dctx = ZSTD_createDCtx())) return nelf__fail(r, NELF_ERR_OUT_OF_MEMORY, "cannot create a zstd context");
    if ((rc = nelf__view(r, 0, have, &view, "the header")) != NELF_OK) return rc;
    memcpy(head, view, (size_t)have);
    if ((rc = nelf__parse_header(r, head, have)) != NELF_OK) return rc;
    /* header checksum over bytes 0..248 and the table */
    count = h->section_count;
    if ((rc = nelf__view(r, NELF_HEADER_SIZE, count * NELF_SECTION_ENTRY_SIZE, &view, "the section table")) != NELF_OK)
        return rc;
    memcpy(hashed, head, 248);
    if (count) memcpy(hashed + 248, view, (size_t)(count * NELF_SECTION_ENTRY_SIZE));
    computed = XXH3_64bits(hashed, (size_t)(248 + count * NELF_SECTION_ENTRY_SIZE));
    if (nelf__checksums_differ(h->header_checksum, computed))
        return nelf__fail(r, NELF_ERR_HEADER_CHECKSUM,
                          "checksum mismatch in header and section table: stored 0x%016llx, computed 0x%016llx",
                          (unsigned long long)h->header_checksum, (unsigned long long)computed);
    for (i = 0; i < count; i++) {
        const unsigned char *e = hashed + 248 + i * NELF_SECTION_ENTRY_SIZE;
        nelf_section *s = &r->sections[i];
        memcpy(s->kind, e, 4);
        s->kind[4] = '\0';
        s->flags = nelf__u16(e + 4);
        s->codec = nelf__u16(e + 6);
        s->shuffle = nelf__u32(e + 8);
        s->offset = nelf__u64(e + 16);
        s->stored_length = nelf__u64(e + 24);
        s->raw_length = nelf__u64(e + 32);
        s->checksum = nelf__u64(e + 40);
    }
    if ((rc = nelf__check_table(r)) != NELF_OK) return rc;
    rank = h->pca_rank;
    r->chunk_count = ((uint64_t)h->brick_count + h->chunk_bricks - 1) / h->chunk_bricks;
    r->bytes_per_brick[0] = 2u * NELF_BRICK_VOXELS;
    r->bytes_per_brick[1] = nelf__coef_bytes_per_brick(h);
    if (r->fine_slot >= 0) r->bytes_per_brick[r->fine_slot] = nelf__fine_bytes_per_brick(h);

    /* BRCK: raw, 6 bytes a brick, so B is bounded by the file size. */
    if ((rc = nelf__whole_section(r, &r->sections[r->known[NELF__BRCK]], &bytes)) != NELF_OK) return rc;
    r->bricks = (uint16_t *)NELF_MALLOC((size_t)h->brick_count * 6 + 1);
    if (!r->bricks) {
        NELF_FREE(bytes);
        return nelf__fail(r, NELF_ERR_OUT_OF_MEMORY, "out of memory for the brick list");
    }
    for (i = 0; i < 3 * (uint64_t)h->brick_count; i++) r->bricks[i] = nelf__u16(bytes + 2 * i);
    NELF_FREE(bytes);
    bytes = NULL;
    for (i = 0; i < h->brick_count; i++) {
        const uint16_t *c = r->bricks + 3 * i;
        int a;
        for (a = 0; a < 3; a++)
            if (c[a] >= h->grid_bricks[a])
                return nelf__fail(r, NELF_ERR_INVALID_BRICKS,
                                  "invalid brick list: brick %llu at [%u, %u, %u] is outside the grid of [%lu, %lu, %lu] bricks",
                                  (unsigned long long)i, c[0], c[1], c[2], (unsigned long)h->grid_bricks[0],
                                  (unsigned long)h->grid_bricks[1], (unsigned long)h->grid_bricks[2]);
        if (i > 0) {
            const uint16_t *p = c - 3;
            int ordered = p[2] != c[2] ? p[2] < c[2] : p[1] != c[1] ? p[1] < c[1] : p[0] < c[0];
            if (!ordered)
                return nelf__fail(r, NELF_ERR_INVALID_BRICKS,
                                  "invalid brick list: brick %llu at [%u, %u, %u] does not follow [%u, %u, %u] in (z, y, x) order (unsorted or repeated)",
                                  (unsigned long long)i, c[0], c[1], c[2], p[0], p[1], p[2]);
        }
    }

    /* PCAB: mean and K basis vectors, all finite. */
    if ((rc = nelf__whole_section(r, &r->sections[r->known[NELF__PCAB]], &bytes)) != NELF_OK) return rc;
    r->pca = (float *)NELF_MALLOC((size_t)(NELF_LT_DIM * (rank + 1)) * sizeof(float));
    if (!r->pca) {
        NELF_FREE(bytes);
        return nelf__fail(r, NELF_ERR_OUT_OF_MEMORY, "out of memory for the PCA model");
    }
    for (i = 0; i < NELF_LT_DIM * (rank + 1); i++) r->pca[i] = nelf__f32(bytes + 4 * i);
    NELF_FREE(bytes);
    bytes = NULL;
    for (i = 0; i < NELF_LT_DIM; i++)
        if (!nelf__finite32(r->pca[i]))
            return nelf__fail(r, NELF_ERR_NONFINITE_PCA, "non-finite value in PCA mean element %llu", (unsigned long long)i);
    for (i = NELF_LT_DIM; i < NELF_LT_DIM * (rank + 1); i++)
        if (!nelf__finite32(r->pca[i]))
            return nelf__fail(r, NELF_ERR_NONFINITE_PCA, "non-finite value in PCA basis component %llu element %llu",
                              (unsigned long long)(i / NELF_LT_DIM - 1), (unsigned long long)(i % NELF_LT_DIM));

    /* QPRM: present exactly with 8-bit coefficients. */
    if (h->coefficient_encoding == NELF_ENCODING_U8_AFFINE) {
        if (r->known[NELF__QPRM] < 0) return nelf__fail(r, NELF_ERR_MISSING_SECTION, "required section QPRM is missing");
        if ((rc = nelf__whole_section(r, &r->sections[r->known[NELF__QPRM]], &bytes)) != NELF_OK) return rc;
        r->qparams = (float *)NELF_MALLOC((size_t)(2 * rank) * sizeof(float));
        if (!r->qparams) {
            NELF_FREE(bytes);
            return nelf__fail(r, NELF_ERR_OUT_OF_MEMORY, "out of memory for QPRM");
        }
        for (i = 0; i < rank; i++) {
            r->qparams[i] = nelf__f32(bytes + 8 * i);
            r->qparams[rank + i] = nelf__f32(bytes + 8 * i + 4);
        }
        NELF_FREE(bytes);
        bytes = NULL;
        if ((rc = nelf__check_qparams(r, r->qparams, r->qparams + rank, rank, "QPRM")) != NELF_OK) return rc;
    } else if (r->known[NELF__QPRM] >= 0) {
        return nelf__fail(r, NELF_ERR_UNEXPECTED_QPRM,
                          "invalid header field coefficient_encoding: f16 coefficients need no QPRM section, but one is present");
    }

    /* VDEP: the view-dependent part's sizes, lobes, basis and 8-bit parameters; then
     * VCOF's entry, whose brick size VDEP gives. */
    if (r->has_view) {
        if ((rc = nelf__whole_section(r, &r->sections[r->known[NELF__VDEP]], &bytes)) != NELF_OK) return rc;
        rc = nelf__parse_view(r, bytes, r->sections[r->known[NELF__VDEP]].raw_length);
        NELF_FREE(bytes);
        bytes = NULL;
        if (rc != NELF_OK) return rc;
        r->bytes_per_brick[2] = (uint64_t)NELF_BRICK_VOXELS * r->view.coefficients_per_voxel *
                                (r->view.encoding == NELF_ENCODING_F16 ? 2u : 1u);
        if ((rc = nelf__check_chunked_entry(r, &r->sections[r->known[NELF__VCOF]], r->bytes_per_brick[2])) != NELF_OK)
            return rc;
    }

    /* VREF: the reflection part's eyes, exponent and 8-bit parameters (VRCO's entry was
     * checked with the table: its brick size is fixed). */
    if (r->has_reflection) {
        if ((rc = nelf__whole_section(r, &r->sections[r->known[NELF__VREF]], &bytes)) != NELF_OK) return rc;
        rc = nelf__parse_reflection(r, bytes, r->sections[r->known[NELF__VREF]].raw_length);
        NELF_FREE(bytes);
        bytes = NULL;
        if (rc != NELF_OK) return rc;
        r->bytes_per_brick[2] = NELF__REFLECTION_BYTES_PER_BRICK;
    }

    /* META: a JSON object. */
    if (r->known[NELF__META] >= 0) {
        const nelf_section *s = &r->sections[r->known[NELF__META]];
        if ((rc = nelf__whole_section(r, s, &r->meta)) != NELF_OK) return rc;
        r->meta_length = (size_t)s->raw_length;
        if ((rc = nelf__check_metadata(r, r->meta, r->meta_length)) != NELF_OK) return rc;
    }

    for (i = 0; i < (uint64_t)r->chunked; i++)
        if ((rc = nelf__chunk_table(r, (int)i)) != NELF_OK) return rc;

    r->brick_density = (float *)NELF_MALLOC(NELF_BRICK_VOXELS * sizeof(float));
    r->brick_coef = (float *)NELF_MALLOC((size_t)(NELF_BRICK_VOXELS * rank) * sizeof(float));
    if (!r->brick_density || !r->brick_coef) return nelf__fail(r, NELF_ERR_OUT_OF_MEMORY, "out of memory for brick buffers");
    if (r->has_view) {
        r->brick_view = (float *)NELF_MALLOC((size_t)NELF_BRICK_VOXELS * r->view.coefficients_per_voxel * sizeof(float));
        if (!r->brick_view) return nelf__fail(r, NELF_ERR_OUT_OF_MEMORY, "out of memory for brick buffers");
    }
    if (r->has_reflection) {
        r->brick_reflection = (float *)NELF_MALLOC((size_t)NELF__REFLECTION_BYTES_PER_BRICK * sizeof(float));
        if (!r->brick_reflection) return nelf__fail(r, NELF_ERR_OUT_OF_MEMORY, "out of memory for brick buffers");
    }
    if (r->fine_slot >= 0) { /* at most 512 x 64 floats */
        r->brick_fine_density = (float *)NELF_MALLOC((size_t)r->fine_voxels * sizeof(float));
        if (!r->brick_fine_density) return nelf__fail(r, NELF_ERR_OUT_OF_MEMORY, "out of memory for brick buffers");
    }
    r->is_open = 1;
    return nelf__ok(r);
}

NELF_API nelf_result nelf_open_memory(nelf_reader *r, const void *data, size_t size) {
    static const unsigned char empty = 0;
    nelf_result rc;
    if (!r) return NELF_ERR_INVALID_ARGUMENT;
    nelf__release(r);
    if (!data && size) return nelf__fail(r, NELF_ERR_INVALID_ARGUMENT, "NULL data with a non-zero size");
    r->mem = data ? (const unsigned char *)data : &empty;
    r->file_size = size;
    rc = nelf__open(r);
    if (rc != NELF_OK) {
        nelf_result keep = r->status;
        char detail[NELF_DETAIL_SIZE];
        memcpy(detail, r->detail, sizeof detail);
        nelf__release(r);
        r->status = keep;
        memcpy(r->detail, detail, sizeof detail);
    }
    return rc;
}

NELF_API nelf_result nelf_open_path(nelf_reader *r, const char *path) {
    long end;
    nelf_result rc;
    if (!r) return NELF_ERR_INVALID_ARGUMENT;
    nelf__release(r);
    if (!path) return nelf__fail(r, NELF_ERR_INVALID_ARGUMENT, "NULL path");
    r->file = fopen(path, "rb");
    if (!r->file) return nelf__fail(r, NELF_ERR_IO, "%s: cannot open", path);
    if (fseek(r->file, 0, SEEK_END) != 0 || (end = ftell(r->file)) < 0) {
        nelf__release(r);
        return nelf__fail(r, NELF_ERR_IO, "%s: cannot find the file size", path);
    }
    r->file_size = (uint64_t)end;
    rc = nelf__open(r);
    if (rc != NELF_OK) {
        nelf_result keep = r->status;
        char detail[NELF_DETAIL_SIZE];
        memcpy(detail, r->detail, sizeof detail);
        nelf__release(r);
        r->status = keep;
        memcpy(r->detail, detail, sizeof detail);
    }
    return rc;
}

NELF_API nelf_result nelf_last_result(const nelf_reader *r) { return r ? r->status : NELF_ERR_INVALID_ARGUMENT; }
NELF_API const char *nelf_error_detail(const nelf_reader *r) {
    if (!r) return "NULL reader";
    return r->detail[0] ? r->detail : nelf_error_string(r->status);
}

/* ---------------------------------------------------------------- chunks and values */

/* Reads chunk `index` of chunked section `which` (DENS, COEF, VCOF or VRCO, DNSF), checks its checksum,
 * decodes it into r->raw[which]; feeds the stored bytes to `section_hash` if given. */
static nelf_result nelf__decode_chunk(nelf_reader *r, int which, uint64_t index, XXH3_state_t *section_hash) {
    const nelf_section *s = &r->sections[r->known[r->chunked_kind[which]]];
    const unsigned char *e = r->chunk_table[which] + index * NELF__CHUNK_ENTRY_SIZE;
    uint64_t offset = s->offset + nelf__u64(e), length = nelf__u64(e + 8), sum = nelf__u64(e + 16), computed;
    uint64_t raw_length = nelf__bricks_in_chunk(&r->header, index) * r->bytes_per_brick[which];
    const unsigned char *stored;
    char what[48];
    nelf_result rc;
    snprintf(what, sizeof what, "section %s chunk %llu", nelf__kinds[r->chunked_kind[which]], (unsigned long long)index);
    if ((rc = nelf__view(r, offset, length, &stored, what)) != NELF_OK) return rc;
    computed = XXH3_64bits(stored, (size_t)length);
    if (nelf__checksums_differ(sum, computed))
        return nelf__fail(r, NELF_ERR_CHUNK_CHECKSUM, "checksum mismatch in %s: stored 0x%016llx, computed 0x%016llx", what,
                          (unsigned long long)sum, (unsigned long long)computed);
    if (section_hash) XXH3_64bits_update(section_hash, stored, (size_t)length);
    if ((rc = nelf__reserve(r, &r->raw[which], &r->raw_cap[which], raw_length)) != NELF_OK) return rc;
    return nelf__decode(r, stored, length, r->raw[which], raw_length, s->shuffle, what);
}

/* Checks `count` f16 densities of `section` (DENS, or DNSF counted in fine voxels)
 * starting at global (fine) voxel `first`. */
static nelf_result nelf__check_density(nelf_reader *r, const char *section, const unsigned char *raw, uint64_t count,
                                       uint64_t first) {
    int is_signed = (r->header.flags & NELF_FLAG_SIGNED_DENSITY) != 0;
    uint64_t i;
    for (i = 0; i < count; i++) {
        uint16_t d = nelf__u16(raw + 2 * i);
        if (!nelf__half_finite(d))
            return nelf__fail(r, NELF_ERR_NONFINITE_DENSITY, "non-finite value in section %s voxel %llu", section,
                              (unsigned long long)(first + i));
        if (!is_signed && nelf__half_negative(d))
            return nelf__fail(r, NELF_ERR_NEGATIVE_DENSITY,
                              "invalid value in section %s voxel %llu: negative density %.9g in a file without the signed-density flag",
                              section, (unsigned long long)(first + i), (double)nelf_half_to_float(d));
    }
    return NELF_OK;
}

/* Checks `count` f16 coefficients of COEF (which = 1, `rank` K) or VCOF (2, R) starting
 * at value index first_voxel * rank. */
static nelf_result nelf__check_f16_coefficients(nelf_reader *r, int which, const unsigned char *raw, uint64_t count,
                                                uint64_t rank, uint64_t first_voxel) {
    uint64_t i;
    for (i = 0; i < count; i++)
        if (!nelf__half_finite(nelf__u16(raw + 2 * i)))
            return nelf__fail(r, NELF_ERR_NONFINITE_COEFFICIENT, "non-finite value in section %s voxel %llu component %llu",
                              nelf__kinds[r->chunked_kind[which]], (unsigned long long)(first_voxel + i / rank),
                              (unsigned long long)(i % rank));
    return NELF_OK;
}

/* Checks one decoded chunk's (or brick's) values: `values` voxels from `first_voxel` (for
 * DNSF, their F^3 fine voxels each). */
static nelf_result nelf__check_values(nelf_reader *r, int which, const unsigned char *raw, uint64_t voxels,
                                      uint64_t first_voxel) {
    if (which == 0) return nelf__check_density(r, "DENS", raw, voxels, first_voxel);
    if (which == r->fine_slot) {
        uint64_t per_voxel = r->fine_voxels / NELF_BRICK_VOXELS;
        return nelf__check_density(r, "DNSF", raw, voxels * per_voxel, first_voxel * per_voxel);
    }
    if (which == 1 && r->header.coefficient_encoding == NELF_ENCODING_F16)
        return nelf__check_f16_coefficients(r, 1, raw, voxels * r->header.pca_rank, r->header.pca_rank, first_voxel);
    if (which == 2 && r->has_view && r->view.encoding == NELF_ENCODING_F16)
        return nelf__check_f16_coefficients(r, 2, raw, voxels * r->view.coefficients_per_voxel,
                                            r->view.coefficients_per_voxel, first_voxel);
    return NELF_OK;
}

/* Dequantizes `count` stored values with `rank` per voxel: offset[k] + scale[k] code in
 * float (scale NULL: f16 values, already checked finite). */
static void nelf__dequantize(float *out, const unsigned char *stored, uint64_t count, uint64_t rank, const float *scale,
                             const float *offset) {
    uint64_t i, k;
    if (scale) {
        for (i = 0; i < count; i += rank)
            for (k = 0; k < rank; k++) out[i + k] = offset[k] + scale[k] * (float)stored[i + k];
    } else {
        for (i = 0; i < count; i++) out[i] = nelf_half_to_float(nelf__u16(stored + 2 * i));
    }
}

/* Checksum of a section read in pieces (file) or at once (memory). */
static nelf_result nelf__stream_checksum(nelf_reader *r, const nelf_section *s, XXH3_state_t *state) {
    uint64_t done = 0, computed;
    char what[32], name[17];
    nelf_result rc;
    snprintf(what, sizeof what, "section %s", nelf__kind_text(s->kind, name));
    XXH3_64bits_reset(state);
    while (done < s->stored_length) {
        const unsigned char *piece;
        uint64_t n = s->stored_length - done;
        if (!r->mem && n > NELF__PIECE) n = NELF__PIECE;
        if ((rc = nelf__view(r, s->offset + done, n, &piece, what)) != NELF_OK) return rc;
        XXH3_64bits_update(state, piece, (size_t)n);
        done += n;
    }
    computed = XXH3_64bits_digest(state);
    if (nelf__checksums_differ(s->checksum, computed))
        return nelf__fail(r, NELF_ERR_SECTION_CHECKSUM, "checksum mismatch in %s: stored 0x%016llx, computed 0x%016llx", what,
                          (unsigned long long)s->checksum, (unsigned long long)computed);
    return NELF_OK;
}

static nelf_result nelf__check_zero(nelf_reader *r, uint64_t offset, uint64_t length) {
    uint64_t done = 0, i;
    nelf_result rc;
    while (done < length) {
        const unsigned char *piece;
        uint64_t n = length - done;
        if (!r->mem && n > NELF__PIECE) n = NELF__PIECE;
        if ((rc = nelf__view(r, offset + done, n, &piece, "padding")) != NELF_OK) return rc;
        for (i = 0; i < n; i++)
            if (piece[i])
                return nelf__fail(r, NELF_ERR_NONZERO_PADDING,
                                  "non-zero padding byte at offset %llu (bytes between sections must be zero)",
                                  (unsigned long long)(offset + done + i));
        done += n;
    }
    return NELF_OK;
}

static nelf_result nelf__verify(nelf_reader *r, XXH3_state_t *state) {
    const nelf_header *h = &r->header;
    uint64_t i, spans[NELF_MAX_SECTIONS + 1][2], cursor;
    uint32_t n = h->section_count, a, b;
    int which;
    nelf_result rc;
    r->cached_chunk = -1;
    for (which = 0; which < r->chunked; which++) {
        const nelf_section *s = &r->sections[r->known[r->chunked_kind[which]]];
        uint64_t computed;
        XXH3_64bits_reset(state);
        XXH3_64bits_update(state, r->chunk_table[which], (size_t)(r->chunk_count * NELF__CHUNK_ENTRY_SIZE));
        for (i = 0; i < r->chunk_count; i++) {
            uint64_t first_voxel = i * h->chunk_bricks * NELF_BRICK_VOXELS;
            uint64_t voxels = nelf__bricks_in_chunk(h, i) * NELF_BRICK_VOXELS;
            if ((rc = nelf__decode_chunk(r, which, i, state)) != NELF_OK) return rc;
            if ((rc = nelf__check_values(r, which, r->raw[which], voxels, first_voxel)) != NELF_OK) return rc;
        }
        computed = XXH3_64bits_digest(state);
        if (nelf__checksums_differ(s->checksum, computed))
            return nelf__fail(r, NELF_ERR_SECTION_CHECKSUM, "checksum mismatch in section %s: stored 0x%016llx, computed 0x%016llx",
                              nelf__kinds[r->chunked_kind[which]], (unsigned long long)s->checksum,
                              (unsigned long long)computed);
    }
    for (a = 0; a < n; a++) {
        const nelf_section *s = &r->sections[a];
        int chunked = 0;
        for (which = 0; which < r->chunked; which++)
            if ((int)a == r->known[r->chunked_kind[which]]) chunked = 1;
        if (chunked) continue;
        if ((rc = nelf__stream_checksum(r, s, state)) != NELF_OK) return rc;
    }
    /* Every byte outside the header, the table and the sections is zero. */
    for (a = 0; a < n; a++) {
        uint64_t start = r->sections[a].offset, end = start + r->sections[a].stored_length;
        b = a;
        while (b > 0 && (spans[b - 1][0] > start || (spans[b - 1][0] == start && spans[b - 1][1] > end))) {
            spans[b][0] = spans[b - 1][0];
            spans[b][1] = spans[b - 1][1];
            b--;
        }
        spans[b][0] = start;
        spans[b][1] = end;
    }
    spans[n][0] = spans[n][1] = h->file_size;
    cursor = NELF_HEADER_SIZE + (uint64_t)n * NELF_SECTION_ENTRY_SIZE;
    for (a = 0; a <= n; a++) {
        if (spans[a][0] > cursor && (rc = nelf__check_zero(r, cursor, spans[a][0] - cursor)) != NELF_OK) return rc;
        if (spans[a][1] > cursor) cursor = spans[a][1];
    }
    return NELF_OK;
}

NELF_API nelf_result nelf_verify(nelf_reader *r) {
    XXH3_state_t *state;
    nelf_result rc;
    if (!r) return NELF_ERR_INVALID_ARGUMENT;
    if (!r->is_open) return nelf__fail(r, NELF_ERR_NOT_OPEN, "no file is open in this reader");
    state = XXH3_createState();
    if (!state) return nelf__fail(r, NELF_ERR_OUT_OF_MEMORY, "cannot create a hash state");
    rc = nelf__verify(r, state);
    XXH3_freeState(state);
    return rc == NELF_OK ? nelf__ok(r) : rc;
}

NELF_API nelf_result nelf_read_brick(nelf_reader *r, uint32_t index, nelf_brick *out) {
    const nelf_header *h;
    uint64_t chunk, within, i, rank, first_voxel;
    const unsigned char *dens, *coef, *view = NULL, *reflection = NULL, *fine = NULL;
    int which;
    nelf_result rc;
    if (!r || !out) return NELF_ERR_INVALID_ARGUMENT;
    if (!r->is_open) return nelf__fail(r, NELF_ERR_NOT_OPEN, "no file is open in this reader");
    h = &r->header;
    if (index >= h->brick_count)
        return nelf__fail(r, NELF_ERR_BRICK_OUT_OF_RANGE, "brick index %lu out of range (asset has %lu bricks)",
                          (unsigned long)index, (unsigned long)h->brick_count);
    chunk = index / h->chunk_bricks;
    if (r->cached_chunk != (int64_t)chunk) {
        r->cached_chunk = -1;
        for (which = 0; which < r->chunked; which++)
            if ((rc = nelf__decode_chunk(r, which, chunk, NULL)) != NELF_OK) return rc;
        r->cached_chunk = (int64_t)chunk;
    }
    within = index - chunk * h->chunk_bricks;
    rank = h->pca_rank;
    first_voxel = (uint64_t)index * NELF_BRICK_VOXELS;
    dens = r->raw[0] + within * r->bytes_per_brick[0];
    coef = r->raw[1] + within * r->bytes_per_brick[1];
    if ((rc = nelf__check_values(r, 0, dens, NELF_BRICK_VOXELS, first_voxel)) != NELF_OK) return rc;
    if ((rc = nelf__check_values(r, 1, coef, NELF_BRICK_VOXELS, first_voxel)) != NELF_OK) return rc;
    nelf__dequantize(r->brick_coef, coef, NELF_BRICK_VOXELS * rank, rank, r->qparams, r->qparams ? r->qparams + rank : NULL);
    if (r->has_view) {
        view = r->raw[2] + within * r->bytes_per_brick[2];
        if ((rc = nelf__check_values(r, 2, view, NELF_BRICK_VOXELS, first_voxel)) != NELF_OK) return rc;
        nelf__dequantize(r->brick_view, view, (uint64_t)NELF_BRICK_VOXELS * r->view.coefficients_per_voxel,
                         r->view.coefficients_per_voxel, r->view.scale, r->view.offset);
    }
    if (r->has_reflection) { /* u8 codes: any is valid */
        reflection = r->raw[2] + within * r->bytes_per_brick[2];
        nelf__dequantize(r->brick_reflection, reflection, NELF__REFLECTION_BYTES_PER_BRICK, NELF_REFLECTION_VALUES,
                         r->reflection.scale, r->reflection.offset);
    }
    if (r->fine_slot >= 0) {
        fine = r->raw[r->fine_slot] + within * r->bytes_per_brick[r->fine_slot];
        if ((rc = nelf__check_values(r, r->fine_slot, fine, NELF_BRICK_VOXELS, first_voxel)) != NELF_OK) return rc;
        for (i = 0; i < r->fine_voxels; i++) r->brick_fine_density[i] = nelf_half_to_float(nelf__u16(fine + 2 * i));
    }
    for (i = 0; i < NELF_BRICK_VOXELS; i++) r->brick_density[i] = nelf_half_to_float(nelf__u16(dens + 2 * i));
    out->index = index;
    memcpy(out->coord, r->bricks + 3 * (uint64_t)index, sizeof out->coord);
    out->density = r->brick_density;
    out->coefficients = r->brick_coef;
    out->stored_coefficients = coef;
    out->view_coefficients = view ? r->brick_view : NULL;
    out->stored_view_coefficients = view;
    out->reflection = reflection ? r->brick_reflection : NULL;
    out->stored_reflection = reflection;
    out->fine_density = fine ? r->brick_fine_density : NULL;
    return nelf__ok(r);
}

/* ---------------------------------------------------------------- accessors */

NELF_API const nelf_header *nelf_get_header(const nelf_reader *r) { return r && r->is_open ? &r->header : NULL; }
NELF_API uint32_t nelf_section_count(const nelf_reader *r) { return r && r->is_open ? r->header.section_count : 0; }
NELF_API const nelf_section *nelf_get_section(const nelf_reader *r, uint32_t i) {
    return r && r->is_open && i < r->header.section_count ? &r->sections[i] : NULL;
}
NELF_API const uint16_t *nelf_brick_coords(const nelf_reader *r) { return r && r->is_open ? r->bricks : NULL; }
NELF_API const float *nelf_pca_mean(const nelf_reader *r) { return r && r->is_open ? r->pca : NULL; }
NELF_API const float *nelf_pca_basis(const nelf_reader *r) { return r && r->is_open ? r->pca + NELF_LT_DIM : NULL; }
NELF_API const float *nelf_quant_scale(const nelf_reader *r) { return r && r->is_open ? r->qparams : NULL; }
NELF_API const float *nelf_quant_offset(const nelf_reader *r) {
    return r && r->is_open && r->qparams ? r->qparams + r->header.pca_rank : NULL;
}
NELF_API const nelf_view *nelf_get_view(const nelf_reader *r) {
    return r && r->is_open && r->has_view ? &r->view : NULL;
}
NELF_API const nelf_reflection *nelf_get_reflection(const nelf_reader *r) {
    return r && r->is_open && r->has_reflection ? &r->reflection : NULL;
}
NELF_API const char *nelf_metadata(const nelf_reader *r, size_t *length) {
    if (!r || !r->is_open) {
        if (length) *length = 0;
        return NULL;
    }
    if (!r->meta) {
        if (length) *length = 2;
        return "{}";
    }
    if (length) *length = r->meta_length;
    return (const char *)r->meta;
}

NELF_API int64_t nelf_find_brick(const nelf_reader *r, uint32_t x, uint32_t y, uint32_t z) {
    uint64_t lo = 0, hi, key;
    if (!r || !r->is_open || x > 0xFFFFu || y > 0xFFFFu || z > 0xFFFFu) return -1;
    hi = r->header.brick_count;
    key = ((uint64_t)z << 32) | ((uint64_t)y << 16) | x;
    while (lo < hi) {
        uint64_t mid = lo + (hi - lo) / 2;
        const uint16_t *c = r->bricks + 3 * mid;
        uint64_t k = ((uint64_t)c[2] << 32) | ((uint64_t)c[1] << 16) | c[0];
        if (k == key) return (int64_t)mid;
        if (k < key) lo = mid + 1;
        else hi = mid;
    }
    return -1;
}

NELF_API nelf_result nelf_voxel_center(const nelf_reader *r, uint32_t brick_index, unsigned i, unsigned j, unsigned k,
                                       double out_m[3]) {
    unsigned local[3];
    int a;
    if (!r || !out_m || i > 7 || j > 7 || k > 7) return NELF_ERR_INVALID_ARGUMENT;
    if (!r->is_open) return NELF_ERR_NOT_OPEN;
    if (brick_index >= r->header.brick_count) return NELF_ERR_BRICK_OUT_OF_RANGE;
    local[0] = i;
    local[1] = j;
    local[2] = k;
    for (a = 0; a < 3; a++) {
        double index = (double)r->bricks[3 * (uint64_t)brick_index + (uint64_t)a] * 8.0 + (double)local[a] + 0.5;
        out_m[a] = r->header.bbox_min_m[a] + index * r->header.voxel_size_m;
    }
    return NELF_OK;
}

NELF_API nelf_result nelf_fine_voxel_center(const nelf_reader *r, uint32_t brick_index, unsigned i, unsigned j,
                                            unsigned k, double out_m[3]) {
    unsigned local[3], edge;
    int a;
    if (!r || !out_m) return NELF_ERR_INVALID_ARGUMENT;
    if (!r->is_open) return NELF_ERR_NOT_OPEN;
    edge = NELF_BRICK_SIZE * r->header.fine_density_factor;
    if (edge == 0 || i >= edge || j >= edge || k >= edge) return NELF_ERR_INVALID_ARGUMENT;
    if (brick_index >= r->header.brick_count) return NELF_ERR_BRICK_OUT_OF_RANGE;
    local[0] = i;
    local[1] = j;
    local[2] = k;
    for (a = 0; a < 3; a++) {
        double index = (double)r->bricks[3 * (uint64_t)brick_index + (uint64_t)a] * (double)edge + (double)local[a] + 0.5;
        out_m[a] = r->header.bbox_min_m[a] + index * r->header.voxel_size_m / (double)r->header.fine_density_factor;
    }
    return NELF_OK;
}

/* ---------------------------------------------------------------- reconstruction, light */

NELF_API void nelf_reconstruct(const nelf_reader *r, const float *coefficients, uint32_t count, float out[NELF_LT_DIM]) {
    uint32_t k, j;
    if (!r || !r->is_open || !out) return;
    memcpy(out, r->pca, NELF_LT_DIM * sizeof(float));
    if (count > r->header.pca_rank) count = r->header.pca_rank;
    for (k = 0; k < count; k++) {
        const float c = coefficients[k];
        const float *b = r->pca + NELF_LT_DIM * (size_t)(k + 1);
        for (j = 0; j < NELF_LT_DIM; j++) out[j] += c * b[j];
    }
}

NELF_API nelf_result nelf_voxel_transport(nelf_reader *r, uint32_t brick_index, uint32_t local, float out[NELF_LT_DIM]) {
    nelf_brick brick;
    nelf_result rc;
    if (!r || !out || local >= NELF_BRICK_VOXELS) return NELF_ERR_INVALID_ARGUMENT;
    if ((rc = nelf_read_brick(r, brick_index, &brick)) != NELF_OK) return rc;
    nelf_reconstruct(r, brick.coefficients + (size_t)local * r->header.pca_rank, r->header.pca_rank, out);
    return NELF_OK;
}

NELF_API void nelf_view_harmonics(const float omega[3], float out[NELF_VIEW_HARMONICS]) {
    const float c0 = 0.2820948f, a = 0.4886025f, b = 1.0925484f, c = 0.31539157f;
    float len, x, y, z;
    int l;
    if (!omega || !out) return;
    len = sqrtf(omega[0] * omega[0] + omega[1] * omega[1] + omega[2] * omega[2]);
    if (!(len > 0.0f && nelf__finite32(len))) {
        for (l = 0; l < NELF_VIEW_HARMONICS; l++) out[l] = 0.0f;
        return;
    }
    x = omega[0] / len;
    y = omega[1] / len;
    z = omega[2] / len;
    out[0] = c0;
    out[1] = a * y;
    out[2] = a * z;
    out[3] = a * x;
    out[4] = b * x * y;
    out[5] = b * y * z;
    out[6] = c * (3.0f * z * z - 1.0f);
    out[7] = b * x * z;
    out[8] = 0.5f * b * (x * x - y * y);
}

NELF_API uint32_t nelf_view_lobe_values(const nelf_reader *r, const float omega[3], float out[NELF_VIEW_HARMONICS]) {
    float y[NELF_VIEW_HARMONICS];
    uint32_t j;
    int l;
    if (!r || !r->is_open || !r->has_view || !omega || !out) return 0;
    nelf_view_harmonics(omega, y);
    for (j = 0; j < r->view.lobe_count; j++) {
        float acc = -0.0f;
        for (l = 0; l < NELF_VIEW_HARMONICS; l++) acc += r->view.lobes[(size_t)j * NELF_VIEW_HARMONICS + (size_t)l] * y[l];
        out[j] = acc;
    }
    return r->view.lobe_count;
}

NELF_API void nelf_add_view_transport(const nelf_reader *r, const float *d, const float omega[3], float out[NELF_LT_DIM]) {
    float lobe[NELF_VIEW_HARMONICS];
    uint32_t j, i, count, rank;
    int e;
    if (!d || !out || (count = nelf_view_lobe_values(r, omega, lobe)) == 0) return;
    rank = r->view.rank;
    for (j = 0; j < count; j++)
        for (i = 0; i < rank; i++) {
            const float w = lobe[j] * d[(size_t)j * rank + i];
            const float *v = r->view.basis + (size_t)NELF_LT_DIM * i;
            for (e = 0; e < NELF_LT_DIM; e++) out[e] += w * v[e];
        }
}

NELF_API nelf_result nelf_voxel_transport_toward(nelf_reader *r, uint32_t brick_index, uint32_t local,
                                                 const float omega[3], float out[NELF_LT_DIM]) {
    nelf_brick brick;
    nelf_result rc;
    if (!r || !out || !omega || local >= NELF_BRICK_VOXELS) return NELF_ERR_INVALID_ARGUMENT;
    if ((rc = nelf_read_brick(r, brick_index, &brick)) != NELF_OK) return rc;
    nelf_reconstruct(r, brick.coefficients + (size_t)local * r->header.pca_rank, r->header.pca_rank, out);
    if (brick.view_coefficients)
        nelf_add_view_transport(r, brick.view_coefficients + (size_t)local * r->view.coefficients_per_voxel, omega, out);
    return NELF_OK;
}

/* ---------------------------------------------------------------- the reflection part */

static float nelf__clamp_unit(float a) { return a < -1.0f ? -1.0f : a > 1.0f ? 1.0f : a; }
static float nelf__sign(float a) { return a >= 0.0f ? 1.0f : -1.0f; }

NELF_API void nelf_octahedral_decode(float u, float v, float out[3]) {
    float x, y, z, len;
    if (!out) return;
    u = nelf__clamp_unit(u);
    v = nelf__clamp_unit(v);
    z = 1.0f - fabsf(u) - fabsf(v);
    if (z < 0.0f) {
        x = (1.0f - fabsf(v)) * nelf__sign(u);
        y = (1.0f - fabsf(u)) * nelf__sign(v);
    } else {
        x = u;
        y = v;
    }
    len = sqrtf(x * x + y * y + z * z);
    out[0] = x / len;
    out[1] = y / len;
    out[2] = z / len;
}

NELF_API float nelf_reflection_voxel(const float values[NELF_REFLECTION_VALUES], float out_normal[3]) {
    if (!values) return 0.0f;
    nelf_octahedral_decode(values[0], values[1], out_normal);
    return values[2] > 0.0f ? values[2] : 0.0f;
}

NELF_API void nelf_lobe_table_corners(const float d[3], uint32_t out_index[4], float out_weight[4]) {
    const float pi = 3.14159265358979323846f, tau = 6.28318530717958647692f;
    const float h = (float)NELF_LOBE_TABLE_HEIGHT, w = (float)NELF_LOBE_TABLE_WIDTH;
    float len, x = 0.0f, y = 1.0f, z = 0.0f, theta, phi, t, s, t0, s0, ft, fs;
    uint32_t row0, row1, col0, col1;
    long cs;
    if (!d || !out_index || !out_weight) return;
    len = sqrtf(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
    if (len > 0.0f && nelf__finite32(len)) {
        x = d[0] / len;
        y = d[1] / len;
        z = d[2] / len;
    }
    theta = acosf(nelf__clamp_unit(y));
    phi = atan2f(x, -z);
    t = theta * h / pi - 0.5f;
    t = t < 0.0f ? 0.0f : t > h - 1.0f ? h - 1.0f : t;
    s = (phi + pi) * w / tau - 0.5f;
    t0 = floorf(t);
    s0 = floorf(s);
    ft = t - t0;
    fs = s - s0;
    row0 = (uint32_t)t0;
    row1 = row0 + 1 < NELF_LOBE_TABLE_HEIGHT ? row0 + 1 : NELF_LOBE_TABLE_HEIGHT - 1;
    cs = (long)s0 % NELF_LOBE_TABLE_WIDTH; /* s0 is in [-1, 128]: wrap it into 0..127 */
    col0 = (uint32_t)(cs < 0 ? cs + NELF_LOBE_TABLE_WIDTH : cs);
    col1 = (col0 + 1) % NELF_LOBE_TABLE_WIDTH;
    out_index[0] = row0 * NELF_LOBE_TABLE_WIDTH + col0;
    out_index[1] = row0 * NELF_LOBE_TABLE_WIDTH + col1;
    out_index[2] = row1 * NELF_LOBE_TABLE_WIDTH + col0;
    out_index[3] = row1 * NELF_LOBE_TABLE_WIDTH + col1;
    out_weight[0] = (1.0f - ft) * (1.0f - fs);
    out_weight[1] = (1.0f - ft) * fs;
    out_weight[2] = ft * (1.0f - fs);
    out_weight[3] = ft * fs;
}

static float nelf__project_vector(const float *v, const float *light_rgb, int c) {
    double acc = -0.0;
    int t;
    for (t = 0; t < NELF_ENV_TEXELS; t++) acc += (double)v[c * NELF_ENV_TEXELS + t] * (double)light_rgb[3 * t + c];
    return (float)acc;
}

NELF_API nelf_result nelf_project_light(const nelf_reader *r, const float *light_rgb, nelf_projected_light *out) {
    uint32_t k;
    int c;
    if (!r || !light_rgb || !out) return NELF_ERR_INVALID_ARGUMENT;
    if (!r->is_open) return NELF_ERR_NOT_OPEN;
    out->rank = r->header.pca_rank;
    for (c = 0; c < 3; c++) out->mean_rgb[c] = nelf__project_vector(r->pca, light_rgb, c);
    for (k = 0; k < out->rank; k++)
        for (c = 0; c < 3; c++)
            out->component_rgb[k][c] = nelf__project_vector(r->pca + NELF_LT_DIM * (size_t)(k + 1), light_rgb, c);
    return NELF_OK;
}

NELF_API void nelf_relight(const nelf_projected_light *light, const float *coefficients, uint32_t count, float out_rgb[3]) {
    uint32_t k;
    int c;
    float rgb[3];
    if (!light || !out_rgb) return;
    rgb[0] = light->mean_rgb[0];
    rgb[1] = light->mean_rgb[1];
    rgb[2] = light->mean_rgb[2];
    if (count > light->rank) count = light->rank;
    for (k = 0; k < count; k++)
        for (c = 0; c < 3; c++) rgb[c] += coefficients[k] * light->component_rgb[k][c];
    out_rgb[0] = rgb[0];
    out_rgb[1] = rgb[1];
    out_rgb[2] = rgb[2];
}

NELF_API void nelf_shade(const float *lt, const float *light_rgb, float out_rgb[3]) {
    int c, t;
    if (!lt || !light_rgb || !out_rgb) return;
    for (c = 0; c < 3; c++) {
        float acc = -0.0f;
        for (t = 0; t < NELF_ENV_TEXELS; t++) acc += lt[c * NELF_ENV_TEXELS + t] * light_rgb[3 * t + c];
        out_rgb[c] = acc;
    }
}

#endif /* NELF_IMPLEMENTATION */
