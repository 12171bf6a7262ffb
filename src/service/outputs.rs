//! A take's model outputs (a C3D's joint angles, forces, moments, powers): read whole from
//! their row (they are small beside the markers), answered by name over a range in their
//! own units, and handed to the C3D writer so an exported file has them where it had them.

use std::sync::Arc;

use super::analog::AnalogAnswer;
use super::budget::{Budget, Holder};
use super::fetch::TimeRange;
use super::{blocking, Error, Result};
use crate::codec::DecodeLimits;
use crate::limits::Limits;
use crate::motion::formats::columns::Column;
use crate::motion::outputs::Outputs;
use crate::store::Store;

/// Take `id`'s model outputs; `None` if it has none.
pub async fn of(store: &Store, id: &str) -> Result<Option<Outputs>> {
    let Some(bytes) = store.outputs(id).await? else {
        return Ok(None);
    };
    let id = id.to_string();
    blocking(move || {
        crate::codec::outputs::decode(&bytes, &DecodeLimits::default())
            .map_err(|e| Error::Corrupt(format!("model outputs of take {id}: {e}")))
    })
    .await?
    .map(Some)
}

/// Outputs `names` (all when empty) of frames `range` of take `id`, three columns each
/// (`name.x`, `.y`, `.z`) in the output's unit, within [`Limits::answer_samples`].
pub async fn answer(
    store: &Store,
    budget: &Arc<Budget>,
    holder: Holder,
    limits: &Limits,
    id: &str,
    range: TimeRange,
    names: &[String],
) -> Result<AnalogAnswer> {
    let take = super::fetch::take(store, id).await?;
    let (start, end) = range.resolve(take.frames, take.fps)?;
    let described = &take.meta.outputs;
    if described.is_empty() {
        return Err(Error::Unsatisfiable(format!(
            "take {id} has no model outputs (a C3D's POINT:ANGLES, FORCES, MOMENTS, POWERS)"
        )));
    }
    let picked: Vec<usize> = if names.is_empty() {
        (0..described.len()).collect()
    } else {
        names
            .iter()
            .map(|n| {
                described.iter().position(|o| &o.name == n).ok_or_else(|| {
                    let all: Vec<&str> = described.iter().map(|o| o.name.as_str()).collect();
                    Error::InvalidRequest(format!(
                        "{n:?} is not a model output of take {id}; it has {}",
                        all.join(", ")
                    ))
                })
            })
            .collect::<Result<_>>()?
    };
    let values = (end - start) as u64 * picked.len() as u64 * 3;
    if values > limits.answer_samples.saturating_mul(3) {
        return Err(Error::InvalidRequest(format!(
            "{values} output values is over the limit of {} in one answer; ask for fewer \
             outputs or a shorter range",
            limits.answer_samples.saturating_mul(3)
        )));
    }
    // Every output of every frame decoded (4 bytes), the values answered (8) and their text.
    let whole = take.frames as u64 * described.len() as u64 * 3 * 4;
    let mut reservation = budget.reservation(holder);
    reservation
        .grow_to(whole + values * (8 + 25))
        .map_err(|r| Error::Busy(format!("{}; retry shortly", r.reason("output answers"))))?;
    let outputs = of(store, id)
        .await?
        .ok_or_else(|| Error::Corrupt(format!("take {id}: its model outputs are not stored")))?;
    if outputs.frames() != take.frames {
        return Err(Error::Corrupt(format!(
            "take {id}: {} frames of model outputs for {} frames",
            outputs.frames(),
            take.frames
        )));
    }
    let columns = picked
        .iter()
        .flat_map(|&o| {
            let out = &outputs.outputs[o];
            ["x", "y", "z"].map(|a| Column {
                label: format!("{}.{a}", out.name),
                unit: out.unit.clone(),
            })
        })
        .collect();
    let values = blocking(move || {
        let mut v = Vec::with_capacity((end - start) * picked.len() * 3);
        for f in start..end {
            for &o in &picked {
                v.extend(outputs.get(f, o).map(f64::from));
            }
        }
        v
    })
    .await?;
    Ok(AnalogAnswer {
        start_frame: start,
        frames: end - start,
        rate: take.fps,
        t0: start as f64 / crate::motion::rate::nominal(take.fps),
        columns,
        values,
        reservation,
    })
}
