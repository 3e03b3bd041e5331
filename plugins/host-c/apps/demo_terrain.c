/* The demo's height field (demo_terrain.h). */
#include "demo_terrain.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#ifdef WXSKY_GL_ES
#define GLSL_HEAD "#version 300 es\nprecision highp float;\n"
#else
#define GLSL_HEAD "#version 330 core\n"
#endif

static double smooth01(double x) {
    x = x < 0.0 ? 0.0 : x > 1.0 ? 1.0 : x;
    return x * x * (3.0 - 2.0 * x);
}

double terrain_height_m(double e, double n) {
    /* rolling farmland, a ridge across the way north with a saddle, and the runway's flat */
    double rolling = 28.0 * sin(e / 1700.0) * cos(n / 2100.0) + 12.0 * sin((e + 0.7 * n) / 650.0);
    double across = (n - RIDGE_NORTH_M - 600.0 * sin(e / 4000.0)) / 1300.0;
    double peaks = 0.62 + 0.25 * cos(e / 2600.0) + 0.13 * cos(e / 900.0 + 1.3);
    double ridge = RIDGE_HEIGHT_M * exp(-across * across) * peaks;
    double h = rolling + ridge;
    /* the airfield: flat within 250 m of the runway, blending out over the next 400 m */
    double de = fabs(e) - RUNWAY_HALF_WIDTH_M - 220.0, dn = fabs(n) - RUNWAY_HALF_LEN_M - 250.0;
    double d = fmax(de, dn);
    return h * smooth01(d / 400.0);
}

static const char *VERTEX_SRC =
    GLSL_HEAD
    "uniform mat4 u_view_proj;\n"
    "layout(location = 0) in vec3 a_pos;\n"
    "layout(location = 1) in vec3 a_normal;\n"
    "out vec3 v_pos;\n"
    "out vec3 v_normal;\n"
    "void main() {\n"
    "    v_pos = a_pos;\n"
    "    v_normal = a_normal;\n"
    "    gl_Position = u_view_proj * vec4(a_pos, 1.0);\n"
    "}\n";

static const char *FRAGMENT_SRC =
    GLSL_HEAD
    "uniform vec3 u_eye;\n"
    "uniform vec3 u_sun;\n"
    "uniform float u_ground_m;\n"
    "uniform float u_sun_light;\n"
    "uniform int u_mode;\n"
    "in vec3 v_pos;\n"
    "in vec3 v_normal;\n"
    "out vec4 frag;\n"
    WXSKY_GL_SHADOW_GLSL
    "float hash(vec2 c) { return fract(sin(dot(c, vec2(127.1, 311.7))) * 43758.5453); }\n"
    "void main() {\n"
    "    if (u_mode == 1) {\n"
    "        float dm = length(v_pos - u_eye) / 100.0;\n"
    "        frag = vec4(min(floor(dm), 255.0) / 255.0, fract(dm), 0.0, 1.0);\n"
    "        return;\n"
    "    }\n"
    "    vec3 n = normalize(v_normal);\n"
    "    float h = v_pos.z - u_ground_m;\n"
    "    vec2 field = floor(vec2(v_pos.x / 380.0, v_pos.y / 260.0 + 0.3 * sin(v_pos.x / 900.0)));\n"
    "    float f = hash(field);\n"
    "    vec3 grass = f < 0.45 ? mix(vec3(0.22, 0.34, 0.13), vec3(0.30, 0.40, 0.17), hash(field + 7.0))\n"
    "               : f < 0.7 ? vec3(0.46, 0.42, 0.25) : f < 0.85 ? vec3(0.36, 0.30, 0.20)\n"
    "               : vec3(0.13, 0.22, 0.10);\n"
    "    grass = mix(grass, vec3(0.13, 0.22, 0.10), smoothstep(150.0, 400.0, h));\n"
    "    vec3 rock = vec3(0.43, 0.41, 0.38);\n"
    "    vec3 col = mix(grass, rock, smoothstep(0.80, 0.65, n.z) * 0.8 + smoothstep(450.0, 800.0, h) * 0.6);\n"
    "    col = mix(col, vec3(0.92), smoothstep(880.0, 940.0, h));\n"
    "    vec2 r = abs(v_pos.xy);\n"
    "    if (r.x < " "30.0" " && r.y < " "1500.0" ") {\n"
    "        col = vec3(0.17, 0.17, 0.18);\n"
    "        bool centre = r.x < 0.6 && mod(v_pos.y, 60.0) < 30.0;\n"
    "        bool edge = r.x > 28.5;\n"
    "        bool bars = r.y > 1440.0 && r.y < 1480.0 && mod(r.x, 6.0) < 3.0;\n"
    "        if (centre || edge || bars) col = vec3(0.85);\n"
    "    }\n"
    "    float day = smoothstep(-0.05, 0.15, u_sun.z);\n"
    "    vec3 sun_col = mix(vec3(1.0, 0.55, 0.30), vec3(1.0, 0.96, 0.90), smoothstep(0.0, 0.35, u_sun.z));\n"
    "    float direct = max(dot(n, u_sun), 0.0) * wxsky_shadow(v_pos) * u_sun_light;\n"
    "    vec3 light = vec3(0.38 * day + 0.02) + 0.75 * direct * day * sun_col;\n"
    "    col *= light;\n"
    "    float d = length(v_pos - u_eye);\n"
    "    vec3 haze = vec3(0.62, 0.70, 0.80) * (0.15 + 0.85 * day);\n"
    "    col = mix(haze, col, exp(-d / 30000.0));\n"
    "    frag = vec4(col, 1.0);\n"
    "}\n";

static GLuint compile(GLenum type, const char *src, char *err) {
    GLuint s = glCreateShader(type);
    GLint ok = 0;
    glShaderSource(s, 1, &src, NULL);
    glCompileShader(s);
    glGetShaderiv(s, GL_COMPILE_STATUS, &ok);
    if (!ok) {
        char log[400] = "";
        glGetShaderInfoLog(s, sizeof log, NULL, log);
        snprintf(err, WXSKY_ERROR_MAX, "terrain shader: %s", log);
        glDeleteShader(s);
        return 0;
    }
    return s;
}

int demo_terrain_init(demo_terrain *t, double ground_m) {
    const int n = TERRAIN_CELLS + 1;
    const double step = 2.0 * TERRAIN_HALF_M / TERRAIN_CELLS;
    float *verts = NULL;
    uint32_t *idx = NULL;
    GLuint vs = 0, fs = 0;
    GLint ok = 0;
    int rc = -1;

    memset(t, 0, sizeof *t);
    t->ground_m = ground_m;
    verts = malloc(sizeof *verts * 6 * (size_t)n * n);
    idx = malloc(sizeof *idx * 6 * (size_t)TERRAIN_CELLS * TERRAIN_CELLS);
    if (!verts || !idx) {
        snprintf(t->error, sizeof t->error, "out of memory for the terrain");
        goto done;
    }
    for (int j = 0; j < n; ++j)
        for (int i = 0; i < n; ++i) {
            double e = -TERRAIN_HALF_M + i * step, no = -TERRAIN_HALF_M + j * step;
            double dx = terrain_height_m(e + 5.0, no) - terrain_height_m(e - 5.0, no);
            double dy = terrain_height_m(e, no + 5.0) - terrain_height_m(e, no - 5.0);
            double len = sqrt(dx * dx + dy * dy + 100.0);
            float *v = verts + 6 * ((size_t)j * n + i);
            v[0] = (float)e;
            v[1] = (float)no;
            v[2] = (float)(ground_m + terrain_height_m(e, no));
            v[3] = (float)(-dx / len);
            v[4] = (float)(-dy / len);
            v[5] = (float)(10.0 / len);
        }
    for (int j = 0; j < TERRAIN_CELLS; ++j)
        for (int i = 0; i < TERRAIN_CELLS; ++i) {
            uint32_t a = (uint32_t)(j * n + i), b = a + 1, c = a + (uint32_t)n, d = c + 1;
            uint32_t *q = idx + 6 * ((size_t)j * TERRAIN_CELLS + i);
            q[0] = a, q[1] = b, q[2] = d, q[3] = a, q[4] = d, q[5] = c;
        }
    t->index_count = 6 * TERRAIN_CELLS * TERRAIN_CELLS;

    if (!(vs = compile(GL_VERTEX_SHADER, VERTEX_SRC, t->error)) ||
        !(fs = compile(GL_FRAGMENT_SHADER, FRAGMENT_SRC, t->error)))
        goto done;
    t->program = glCreateProgram();
    glAttachShader(t->program, vs);
    glAttachShader(t->program, fs);
    glLinkProgram(t->program);
    glGetProgramiv(t->program, GL_LINK_STATUS, &ok);
    if (!ok) {
        snprintf(t->error, sizeof t->error, "terrain program does not link");
        goto done;
    }
    t->u_view_proj = glGetUniformLocation(t->program, "u_view_proj");
    t->u_eye = glGetUniformLocation(t->program, "u_eye");
    t->u_sun = glGetUniformLocation(t->program, "u_sun");
    t->u_ground_m = glGetUniformLocation(t->program, "u_ground_m");
    t->u_sun_light = glGetUniformLocation(t->program, "u_sun_light");
    t->u_mode = glGetUniformLocation(t->program, "u_mode");

    glGenVertexArrays(1, &t->vao);
    glBindVertexArray(t->vao);
    glGenBuffers(1, &t->vbo);
    glBindBuffer(GL_ARRAY_BUFFER, t->vbo);
    glBufferData(GL_ARRAY_BUFFER, (GLsizeiptr)(sizeof *verts * 6 * (size_t)n * n), verts,
                 GL_STATIC_DRAW);
    glGenBuffers(1, &t->ibo);
    glBindBuffer(GL_ELEMENT_ARRAY_BUFFER, t->ibo);
    glBufferData(GL_ELEMENT_ARRAY_BUFFER, (GLsizeiptr)(sizeof *idx * (size_t)t->index_count),
                 idx, GL_STATIC_DRAW);
    glEnableVertexAttribArray(0);
    glVertexAttribPointer(0, 3, GL_FLOAT, GL_FALSE, 6 * sizeof(float), (void *)0);
    glEnableVertexAttribArray(1);
    glVertexAttribPointer(1, 3, GL_FLOAT, GL_FALSE, 6 * sizeof(float),
                          (void *)(3 * sizeof(float)));
    glBindVertexArray(0);
    if (glGetError() != GL_NO_ERROR) {
        snprintf(t->error, sizeof t->error, "GL error making the terrain");
        goto done;
    }
    rc = 0;
done:
    if (vs)
        glDeleteShader(vs);
    if (fs)
        glDeleteShader(fs);
    free(verts);
    free(idx);
    return rc;
}

/* out = a * b, column-major 4x4 */
static void mat_mul(const double a[16], const double b[16], float out[16]) {
    for (int c = 0; c < 4; ++c)
        for (int r = 0; r < 4; ++r) {
            double s = 0.0;
            for (int k = 0; k < 4; ++k)
                s += a[k * 4 + r] * b[c * 4 + k];
            out[c * 4 + r] = (float)s;
        }
}

int demo_terrain_draw(demo_terrain *t, wxsky_gl_compositor *gl, const wxsky_record *rec,
                      const double view[16], const double proj[16], int distance) {
    float vp[16];
    GLenum code;
    mat_mul(proj, view, vp);
    glUseProgram(t->program);
    glUniformMatrix4fv(t->u_view_proj, 1, GL_FALSE, vp);
    glUniform3f(t->u_eye, (float)rec->position_m[0], (float)rec->position_m[1],
                (float)rec->position_m[2]);
    glUniform3f(t->u_sun, (float)rec->sun_direction_enu[0], (float)rec->sun_direction_enu[1],
                (float)rec->sun_direction_enu[2]);
    glUniform1f(t->u_ground_m, (float)t->ground_m);
    glUniform1f(t->u_sun_light, 1.0f);
    glUniform1i(t->u_mode, distance ? 1 : 0);
    /* the frame's cloud shadows, on texture unit 2 (the compositor's are 0 and 1) */
    if (wxsky_gl_shadow_bind(gl, t->program, 2) != WXSKY_OK) {
        snprintf(t->error, sizeof t->error, "cloud shadows: %s", wxsky_gl_error(gl));
        return -1;
    }
    glDisable(GL_BLEND);
    glEnable(GL_DEPTH_TEST);
    glDepthFunc(GL_LESS);
    glDepthMask(GL_TRUE);
    glBindVertexArray(t->vao);
    glDrawElements(GL_TRIANGLES, t->index_count, GL_UNSIGNED_INT, (void *)0);
    glBindVertexArray(0);
    if ((code = glGetError()) != GL_NO_ERROR) {
        snprintf(t->error, sizeof t->error, "drawing the terrain: GL error 0x%x", (unsigned)code);
        return -1;
    }
    return 0;
}

void demo_terrain_free(demo_terrain *t) {
    if (t->program)
        glDeleteProgram(t->program);
    if (t->vbo)
        glDeleteBuffers(1, &t->vbo);
    if (t->ibo)
        glDeleteBuffers(1, &t->ibo);
    if (t->vao)
        glDeleteVertexArrays(1, &t->vao);
    memset(t, 0, sizeof *t);
}
