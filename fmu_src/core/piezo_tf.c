/* piezo_tf.c - second-order discrete transfer function. See piezo_tf.h. */
#include <math.h>
#include <string.h>
#include "piezo_tf.h"

piezo_status piezo_tf_init(piezo_tf *tf, const piezo_tf_params *params, piezo_diag *diag)
{
    if (!tf || !params) return PIEZO_ERR_NULL;
    if (!isfinite(params->b1)) return piezo_refuse(diag, "tf.b1", "finite", params->b1);
    if (!isfinite(params->b2)) return piezo_refuse(diag, "tf.b2", "finite", params->b2);
    /* Jury test for z^2 + a1 z + a2: both poles strictly inside the unit circle. */
    if (!(isfinite(params->a2) && fabs(params->a2) < 1.0))
        return piezo_refuse(diag, "tf.a2", "|tf.a2| < 1 (stable A)", params->a2);
    if (!(isfinite(params->a1) && fabs(params->a1) < 1.0 + params->a2))
        return piezo_refuse(diag, "tf.a1", "|tf.a1| < 1 + tf.a2 (stable A)", params->a1);
    if (params->delay < 0 || params->delay > PIEZO_TF_MAX_DELAY)
        return piezo_refuse(diag, "tf.delay", "0..32 samples", (double)params->delay);

    memset(tf, 0, sizeof *tf);
    tf->a1 = params->a1;
    tf->a2 = params->a2;
    tf->b1 = params->b1;
    tf->b2 = params->b2;
    tf->delay = params->delay;
    return PIEZO_OK;
}

void piezo_tf_reset(piezo_tf *tf)
{
    if (!tf) return;
    tf->x1 = tf->x2 = 0.0;
    memset(tf->u_ring, 0, sizeof tf->u_ring);
    tf->head = 0;
}

/* The input ring after pushing u(k) has u(k) at head' = head - 1 and u(k-i) at
 * head' + i; offsets 1..33 hold the pushed-out past, so x(k+1) can be read
 * before anything is written. */
static int ring_index(int head, int offset)
{
    int i = head + offset;
    return i >= PIEZO_TF_INPUT_RING ? i - PIEZO_TF_INPUT_RING : i;
}

piezo_status piezo_tf_eval(const piezo_tf *tf, double u, double *x_next)
{
    int head;
    double u_d0, u_d1;
    if (!tf || !x_next) return PIEZO_ERR_NULL;
    if (!isfinite(u)) return PIEZO_ERR_NONFINITE;
    head = tf->head == 0 ? PIEZO_TF_INPUT_RING - 1 : tf->head - 1;
    u_d0 = tf->delay == 0 ? u : tf->u_ring[ring_index(head, tf->delay)];   /* u(k-delay)   */
    u_d1 = tf->u_ring[ring_index(head, tf->delay + 1)];                     /* u(k-1-delay) */
    /* x(k+1) = -a1 x(k) - a2 x(k-1) + b1 u(k-delay) + b2 u(k-1-delay) */
    *x_next = -tf->a1 * tf->x1 - tf->a2 * tf->x2 + tf->b1 * u_d0 + tf->b2 * u_d1;
    return PIEZO_OK;
}

void piezo_tf_commit(piezo_tf *tf, double u, double x_next)
{
    tf->head = tf->head == 0 ? PIEZO_TF_INPUT_RING - 1 : tf->head - 1;
    tf->u_ring[tf->head] = u;
    tf->x2 = tf->x1;
    tf->x1 = x_next;
}

piezo_status piezo_tf_step(piezo_tf *tf, double u, double *x_next)
{
    piezo_status st;
    if (!tf) return PIEZO_ERR_NULL;
    st = piezo_tf_eval(tf, u, x_next);
    if (st == PIEZO_OK) piezo_tf_commit(tf, u, *x_next);
    return st;
}

const char *piezo_tf_check(const piezo_tf *tf)
{
    int i;
    if (!tf) return "transfer function missing";
    if (tf->delay < 0 || tf->delay > PIEZO_TF_MAX_DELAY) return "tf.delay outside 0..32";
    if (tf->head < 0 || tf->head >= PIEZO_TF_INPUT_RING) return "tf input ring index out of range";
    if (!(isfinite(tf->a1) && isfinite(tf->a2) && isfinite(tf->b1) && isfinite(tf->b2)
          && isfinite(tf->x1) && isfinite(tf->x2)))
        return "tf coefficients or state not finite";
    for (i = 0; i < PIEZO_TF_INPUT_RING; ++i)
        if (!isfinite(tf->u_ring[i])) return "tf input ring not finite";
    return NULL;
}
