/*
 * model_table.c - print one model's variable table (fmu_src/<Model>/model.c)
 * as JSON, so that tests can compare the model descriptions and the harness
 * with the C code itself instead of a re-typed list.
 *
 * Compiled by tests/test_variable_sources.py once per model, against that
 * model's config.h (first on the include path), its model.c and the core:
 *
 *     cc -std=c99 -I fmu_src/<Model> -I fmu_src/fmi -I fmu_src/core \
 *        tests/model_table/model_table.c fmu_src/<Model>/model.c <fmu_src/core/ *.c> -lm
 *
 * Output, one JSON object:
 *   model, guid           MODEL_IDENTIFIER_STRING, MODEL_GUID
 *   n_variables           MODEL_N_VARIABLES (FMI 3.0: the value reference of time)
 *   param_structs         where the core's parameter structs lie in ModelData: {field:
 *                         [offset, size]}, ModelData.params, or the fields config.h names
 *                         in MODEL_PARAM_STRUCTS (a model of several blocks)
 *   data_size             sizeof(ModelData): every offset lies inside it
 *   real_size, int_size   the sizes the glue reads at an offset per type
 *   variables             entry i of model_variables (value reference i):
 *                         name (null when the table has no entry there), type,
 *                         causality, offset, and start: the value
 *                         model_set_start_values leaves at the offset (Real as
 *                         %.17g, which reads back to the same double), null for
 *                         outputs (computed, no start value) and for an offset past the data
 */
#include <stdio.h>
#include <string.h>

#include "fmu_model.h"

static ModelData data;  /* static: zeroed, and not on the stack (it can be large) */

/* X(field) for every core parameter struct in ModelData */
#ifndef MODEL_PARAM_STRUCTS
#define MODEL_PARAM_STRUCTS X(params)
#endif

static void print_string(const char *s)
{
    putchar('"');
    for (; *s != '\0'; s++) {
        if (*s == '"' || *s == '\\')
            putchar('\\');
        putchar(*s);
    }
    putchar('"');
}

static const char *type_name(model_type t)
{
    return t == MODEL_REAL ? "Real" : t == MODEL_INTEGER ? "Integer" : t == MODEL_BOOLEAN ? "Boolean" : "?";
}

static const char *causality_name(model_causality c)
{
    return c == MODEL_PARAMETER ? "parameter" : c == MODEL_INPUT ? "input" : c == MODEL_OUTPUT ? "output" : "?";
}

int main(void)
{
    size_t i;
    model_set_start_values(&data);
    printf("{\"model\": ");
    print_string(MODEL_IDENTIFIER_STRING);
    printf(", \"guid\": ");
    print_string(MODEL_GUID);
    printf(", \"n_variables\": %d, \"param_structs\": {", (int)MODEL_N_VARIABLES);
    {
        const char *sep = "";
#define X(field) printf("%s\"" #field "\": [%zu, %zu]", sep, offsetof(ModelData, field), sizeof data.field), sep = ", ";
        MODEL_PARAM_STRUCTS
#undef X
    }
    printf("}, \"data_size\": %zu, \"real_size\": %zu, \"int_size\": %zu,\n \"variables\": [", sizeof data,
           sizeof(double), sizeof(int));
    for (i = 0; i < (size_t)MODEL_N_VARIABLES; i++) {
        const model_variable *v = &model_variables[i];
        const char *at = (const char *)&data + v->offset;
        printf("%s\n  {\"vr\": %zu, \"name\": ", i == 0 ? "" : ",", i);
        if (v->name == NULL) {          /* a gap in the designated initializers */
            printf("null}");
            continue;
        }
        print_string(v->name);
        printf(", \"type\": \"%s\", \"causality\": \"%s\", \"offset\": %zu, \"start\": ", type_name(v->type),
               causality_name(v->causality), v->offset);
        if (v->causality == MODEL_OUTPUT
            || v->offset + (v->type == MODEL_REAL ? sizeof(double) : sizeof(int)) > sizeof data) {
            printf("null}");
        } else if (v->type == MODEL_REAL) {
            double x;
            memcpy(&x, at, sizeof x);
            printf("%.17g}", x);
        } else {
            int n;
            memcpy(&n, at, sizeof n);
            printf("%d}", n);
        }
    }
    printf("\n]}\n");
    return 0;
}
