/* Prints a .nelf file's size, the radiance of one voxel under white light, its reflection part and fine density.
 * cc -std=c99 -O2 -I include include/example.c -o nelf_example -lzstd -lxxhash -lm */
#define NELF_IMPLEMENTATION
#include "nelf.h"
#include <stdio.h>

int main(int argc, char **argv) {
    static nelf_projected_light light; /* 4.6 KiB: keep it off the stack */
    float white[NELF_ENV_TEXELS * 3], rgb[3];
    nelf_brick brick;
    nelf_reader *reader = nelf_create();
    nelf_result rc = argc == 2 && reader ? nelf_open_path(reader, argv[1]) : NELF_ERR_INVALID_ARGUMENT;
    if (rc == NELF_OK) rc = nelf_verify(reader); /* optional: checks every byte */
    if (rc != NELF_OK) {
        fprintf(stderr, "%s: %s\n", nelf_error_string(rc), reader ? nelf_error_detail(reader) : "");
        nelf_destroy(reader);
        return 1;
    }
    const nelf_header *h = nelf_get_header(reader);
    printf("%u bricks, rank %u, %.1f mm voxels\n", (unsigned)h->brick_count, (unsigned)h->pca_rank,
           1000.0 * h->voxel_size_m);
    const nelf_reflection *part = nelf_get_reflection(reader); /* format 1.3, NULL without one */
    if (part) printf("reflection part: lobe exponent %g, %u eyes\n", part->exponent, (unsigned)part->eye_count);
    if (h->fine_density_factor) /* format 1.4: the density again, on a lattice F times finer per axis */
        printf("fine density: %u x finer per axis\n", (unsigned)h->fine_density_factor);
    for (int t = 0; t < NELF_ENV_TEXELS * 3; t++) white[t] = 1.0f;
    nelf_project_light(reader, white, &light);          /* once per lighting change */
    if (h->brick_count > 0 && (rc = nelf_read_brick(reader, 0, &brick)) == NELF_OK) {
        const float *c = brick.coefficients + 100 * h->pca_rank; /* voxel 100 of brick 0 */
        nelf_relight(&light, c, h->pca_rank, rgb);
        printf("brick (%u, %u, %u) voxel 100: density %g 1/m, radiance %g %g %g\n", brick.coord[0], brick.coord[1],
               brick.coord[2], brick.density[100], rgb[0], rgb[1], rgb[2]);
        if (brick.reflection) { /* its normal and the scale of its glossy lobe */
            float n[3], s = nelf_reflection_voxel(brick.reflection + 100 * NELF_REFLECTION_VALUES, n);
            printf("voxel 100 reflects: normal %.3f %.3f %.3f, scale %g\n", n[0], n[1], n[2], s);
        }
        if (brick.fine_density) { /* 512 F^3 values; fine voxel (i, j, k) at i + 8F (j + 8F k) */
            unsigned edge = 8 * h->fine_density_factor, last = edge * edge * edge - 1;
            printf("fine voxel %u: density %g 1/m\n", last, brick.fine_density[last]);
        }
    }
    if (rc != NELF_OK) fprintf(stderr, "%s\n", nelf_error_detail(reader));
    nelf_destroy(reader);
    return rc == NELF_OK ? 0 : 1;
}
