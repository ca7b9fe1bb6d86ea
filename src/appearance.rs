//! The appearance model (\[blend\] §3): PCA of shape-normalised RGB textures, the pixels inside
//! the reference mesh, `a ≈ ā + P_a b_a`. Independent of the shape model: the two are never
//! combined by a third PCA, because independent models animate more naturally.

use crate::pca::{Components, PcaError, PcaModel};

/// RGB appearance model over the mask pixels of a reference frame (values in grey levels).
#[derive(Clone, Debug, PartialEq)]
pub struct AppearanceModel {
    /// PCA of the textures (`n_pixels × 3` values each).
    pub pca: PcaModel,
}

impl AppearanceModel {
    /// Fits the model to textures (each `n_pixels × 3`, mask order).
    pub fn build(textures: &[Vec<f32>], keep: Components) -> Result<Self, PcaError> {
        let rows: Vec<&[f32]> = textures.iter().map(|t| t.as_slice()).collect();
        Ok(AppearanceModel {
            pca: PcaModel::fit(&rows, keep)?,
        })
    }

    /// Appearance parameters `b_a`.
    pub fn n_params(&self) -> usize {
        self.pca.n_components()
    }

    /// Number of mask pixels the model covers.
    pub fn n_pixels(&self) -> usize {
        self.pca.dim() / 3
    }

    /// `b_a = P_aᵀ (a − ā)`.
    pub fn project(&self, texture: &[f32]) -> Vec<f32> {
        self.pca.project(texture)
    }

    /// `a = ā + P_a b_a`.
    pub fn instance(&self, b: &[f32]) -> Vec<f32> {
        self.pca.reconstruct(b)
    }
}
