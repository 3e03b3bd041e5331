/* The demo host's own scenery: a height field around the observer with a runway, drawn with
 * depth, lit by the frame's sun and darkened by the frame's cloud shadows. What a simulator
 * draws instead is its own business; this is the smallest scene that shows a host's geometry
 * and wxsky's clouds hiding each other correctly. */
#ifndef WXSKY_APPS_DEMO_TERRAIN_H
#define WXSKY_APPS_DEMO_TERRAIN_H

#include <stdint.h>

#include "gl_api.h"
#include "wxsky_host.h"
#include "wxsky_host_gl.h"

/* The scene: its extent and the features the camera path and the tests rely on. */
#define TERRAIN_HALF_M 20000.0  /* the height field spans +-20 km east and north */
#define TERRAIN_CELLS 400       /* 100 m cells */
#define RUNWAY_HALF_LEN_M 1500.0 /* along north, centred on the observer */
#define RUNWAY_HALF_WIDTH_M 30.0
#define RIDGE_NORTH_M 7000.0    /* a ridge across the way, 7 km north */
#define RIDGE_HEIGHT_M 950.0

/* Height of the ground above the observer's ground altitude at (east, north), metres. */
double terrain_height_m(double east_m, double north_m);

typedef struct demo_terrain {
    GLuint program, vao, vbo, ibo;
    GLint u_view_proj, u_eye, u_sun, u_ground_m, u_sun_light, u_mode;
    GLsizei index_count;
    double ground_m; /* the observer's ground altitude (MSL) the heights sit on */
    char error[WXSKY_ERROR_MAX];
} demo_terrain;

/* Builds the mesh and the program (a GL context current). 0, or -1 with t->error. */
int demo_terrain_init(demo_terrain *t, double ground_m);
/* Draws it for the record's camera (depth test LESS, depth written), lit by the record's sun
 * and shaded by the cloud-shadow map of the frame last uploaded to `gl`;
 * distance 1: instead of colours, each pixel's distance from the camera in 100 m steps (red:
 * whole steps, capped at 255; green: the fraction), for the tests. Leaves blending disabled and
 * the depth mask on. 0 or -1 with t->error. */
int demo_terrain_draw(demo_terrain *t, wxsky_gl_compositor *gl, const wxsky_record *rec,
                      const double view[16], const double proj[16], int distance);
void demo_terrain_free(demo_terrain *t);

#endif
