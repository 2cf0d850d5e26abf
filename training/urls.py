from django.urls import path

from training import views

app_name = "training"
urlpatterns = [
    path("models/", views.model_list, name="model-list"),
    path("garage/", views.garage, name="garage"),
    path("models/reward-function/", views.reward_editor, name="reward-editor"),
    path("models/reward-function/validate/", views.reward_validation, name="reward-validation"),
    path("tracks/<slug:name>.png", views.track_preview, name="track-preview"),
]
