//! `GET /v1/analyses`: the truth table of analyses (`analysis::registry`), and with `shape_id` which of them apply
//! to that shape's class (the viewer offers only those).

use super::*;
use crate::analysis::registry::{self, AnalysesTable, ShapeClass};

#[derive(Deserialize, utoipa::IntoParams)]
pub struct AnalysesQuery {
    /// A stored shape: say which analyses apply to its class (and why the others do not).
    pub shape_id: Option<String>,
}

/// The truth table of analyses: for each, the shape classes, boundary conditions, orders and extrapolation it
/// supports (every other combination is refused at submission with `unsupported`); with `shape_id`, which apply
/// to that shape.
#[utoipa::path(get, path = "/v1/analyses", tag = "jobs", params(AnalysesQuery), responses(
    (status = 200, description = "the truth table", body = AnalysesTable),
    (status = 404, description = "no such shape", body = crate::service::error::Problem, content_type = "application/problem+json")))]
pub(crate) async fn list_analyses(
    State(st): State<AppState>,
    Query(q): Query<AnalysesQuery>,
) -> Result<Json<AnalysesTable>, ApiError> {
    let class = match &q.shape_id {
        Some(id) => {
            let shape = stored_shape(&st, id)?;
            Some(ShapeClass::of(&shape.validated.shape))
        }
        None => None,
    };
    Ok(Json(registry::table(class)))
}
